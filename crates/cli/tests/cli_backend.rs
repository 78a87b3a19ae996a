//! `--backend`: the GPU backend gives the CPU's answers through the CLI,
//! and without any adapter `gpu` fails with a clear message while `auto`
//! falls back to the CPU. `WGPU_BACKEND=metal` hides every adapter on
//! Linux and Windows (Metal exists only on Apple systems).

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use npyz::WriterBuilder;

fn write_grid(path: &Path) {
    let shape = [9u64, 11, 13];
    let data: Vec<u8> = (0..9 * 11 * 13).map(|i: usize| u8::from((i * 2_654_435_761) % 11 == 4)).collect();
    let file = fs::File::create(path).expect("create npy");
    let mut w = npyz::WriteOptions::<u8>::new()
        .default_dtype()
        .shape(&shape)
        .writer(std::io::BufWriter::new(file))
        .begin_nd()
        .expect("header");
    w.extend(data).expect("data");
    w.finish().expect("finish");
}

fn edt(dir: &Path, backend: &str, out: &str, hide_adapters: bool) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_edtmap"));
    cmd.arg("edt")
        .arg(dir.join("in.npy"))
        .arg(dir.join(out))
        .arg("--nearest")
        .arg(dir.join(format!("idx-{out}")))
        .args(["--backend", backend]);
    if hide_adapters {
        cmd.env("WGPU_BACKEND", "metal");
    }
    cmd.output().expect("edtmap runs")
}

#[cfg(not(target_os = "macos"))]
#[test]
fn no_adapter_gpu_fails_clearly_and_auto_uses_the_cpu() {
    let dir = tempfile::tempdir().expect("temp dir");
    write_grid(&dir.path().join("in.npy"));
    let gpu = edt(dir.path(), "gpu", "gpu.npy", true);
    let err = String::from_utf8_lossy(&gpu.stderr);
    assert!(!gpu.status.success(), "--backend gpu without an adapter must fail");
    assert!(err.contains("--backend gpu") && err.contains("no GPU adapter"), "unclear message: {err}");
    assert!(!dir.path().join("gpu.npy").exists(), "no output on failure");
    let auto = edt(dir.path(), "auto", "auto.npy", true);
    assert!(auto.status.success(), "auto falls back: {}", String::from_utf8_lossy(&auto.stderr));
    assert!(String::from_utf8_lossy(&auto.stderr).contains("using the CPU"));
    let cpu = edt(dir.path(), "cpu", "cpu.npy", true);
    assert!(cpu.status.success());
    assert_eq!(
        fs::read(dir.path().join("auto.npy")).expect("auto"),
        fs::read(dir.path().join("cpu.npy")).expect("cpu")
    );
}

#[test]
fn gpu_gives_the_cpu_answers_when_an_adapter_exists() {
    let dir = tempfile::tempdir().expect("temp dir");
    write_grid(&dir.path().join("in.npy"));
    let gpu = edt(dir.path(), "gpu", "gpu.npy", false);
    if !gpu.status.success() {
        let err = String::from_utf8_lossy(&gpu.stderr);
        assert!(std::env::var("EDTMAP_REQUIRE_GPU").map_or(true, |v| v != "1"), "EDTMAP_REQUIRE_GPU=1 but: {err}");
        eprintln!("skipping: {err}");
        return;
    }
    let cpu = edt(dir.path(), "cpu", "cpu.npy", false);
    assert!(cpu.status.success());
    for name in ["gpu.npy", "idx-gpu.npy"] {
        let cpu_name = name.replace("gpu", "cpu");
        assert_eq!(
            fs::read(dir.path().join(name)).expect("gpu"),
            fs::read(dir.path().join(cpu_name)).expect("cpu"),
            "{name}"
        );
    }
}

/// A GPU run's `report.json` counts each frame's device traffic: the
/// batch EDT's field comes down (8 bytes per window voxel at least in the
/// wavefront mode, which runs it every frame), something goes up, work is
/// dispatched, device memory is held and device time reported; a CPU run
/// has no such fields.
#[test]
fn gpu_reports_count_device_traffic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let run = |backend: &str| {
        let out = dir.path().join(backend);
        let done = Command::new(env!("CARGO_BIN_EXE_edtmap"))
            .args([
                "run",
                "--scene",
                "planar",
                "--frames",
                "3",
                "--integration",
                "wavefront",
                "--backend",
                backend,
                "--out",
            ])
            .arg(&out)
            .output()
            .expect("edtmap runs");
        (done, out.join("report.json"))
    };
    let (gpu, report) = run("gpu");
    if !gpu.status.success() {
        let err = String::from_utf8_lossy(&gpu.stderr);
        assert!(std::env::var("EDTMAP_REQUIRE_GPU").map_or(true, |v| v != "1"), "EDTMAP_REQUIRE_GPU=1 but: {err}");
        eprintln!("skipping: {err}");
        return;
    }
    let report: serde_json::Value = serde_json::from_slice(&fs::read(report).expect("report")).expect("json");
    let voxels: u64 = report["local_dims"].as_array().expect("dims").iter().map(|d| d.as_u64().expect("dim")).product();
    for frame in report["frames"].as_array().expect("frames") {
        let field = |k: &str| frame[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {frame}"));
        assert!(field("gpu_downloaded_bytes") >= 8.0 * voxels as f64, "{frame}");
        assert!(
            field("gpu_uploaded_bytes") > 0.0 && field("gpu_dispatches") >= 7.0 && field("gpu_submissions") >= 1.0,
            "{frame}"
        );
        // Vulkan reports its allocations; the device times are there (0
        // on an adapter without timestamps).
        assert!(field("gpu_memory_bytes") > 0.0, "{frame}");
        for k in ["gpu_ogm_device_ms", "gpu_batch_edt_device_ms", "gpu_integrate_device_ms"] {
            assert!(field(k) >= 0.0, "{frame}");
        }
    }
    assert!(report["summary"]["gpu_dispatches"]["median"].as_f64().is_some());
    let (cpu, report) = run("cpu");
    assert!(cpu.status.success());
    let report: serde_json::Value = serde_json::from_slice(&fs::read(report).expect("report")).expect("json");
    assert!(report["frames"][0].get("gpu_dispatches").is_none());
}
