//! `edtmap run`'s arguments and what they put in `report.json`: negative
//! slice heights, the default slice, `--eval` on a recording, the printed
//! medians, the threads each frame ran on, the help text.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

fn edtmap(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).output().expect("edtmap runs");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn report(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report.json")).expect("json")
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Regression: `--slice-height -0.4` was refused (`unexpected argument '-0'`).
#[test]
fn negative_slice_height_is_a_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ok, stdout, stderr) =
        edtmap(&["run", "--scene", "planar", "--frames", "2", "--slice-height", "-0.4", "--out", path(dir.path())]);
    assert!(ok, "{stdout}\n{stderr}");
    let slice = &report(dir.path())["slice"];
    assert_eq!(slice["from"], "--slice-height");
    assert_eq!(slice["requested_m"], -0.4);
    assert!(slice["z_m"].is_number(), "{slice}");
    let (ok, _, stderr) =
        edtmap(&["run", "--scene", "planar", "--frames", "1", "--slice-height", "nan", "--out", path(dir.path())]);
    assert!(!ok && stderr.contains("--slice-height") && stderr.contains("finite"), "{stderr}");
}

#[test]
fn default_slice_is_the_densest_observed_layer_and_is_logged() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ok, stdout, stderr) = edtmap(&[
        "-v",
        "run",
        "--scene",
        "room",
        "--frames",
        "2",
        "--construction",
        "raycast",
        "--out",
        path(dir.path()),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let slice = &report(dir.path())["slice"];
    assert_eq!(slice["from"], "densest observed layer");
    assert_eq!(slice["requested_m"], Value::Null);
    let z = slice["z_m"].as_f64().expect("z_m");
    assert!(stderr.contains(&format!("slices at z = {z:.2} m")), "{stderr}");
}

/// Regression: the summary printed `v[n / 2]`, report.json the mean of the
/// two middle values.
#[test]
fn printed_medians_are_report_medians() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ok, stdout, stderr) = edtmap(&["run", "--scene", "planar", "--frames", "4", "--out", path(dir.path())]);
    assert!(ok, "{stdout}\n{stderr}");
    let summary = &report(dir.path())["summary"];
    for (printed, key) in [("occupancy", "ogm_ms"), ("EDT update", "integrate_ms"), ("total", "total_ms")] {
        let median = summary[key]["median"].as_f64().expect("median");
        let text = format!("{printed} median {median:.2} ms");
        assert!(stdout.contains(&text), "{text:?} not in {stdout}");
    }
    // Exact mode has no batch EDT stage: none is printed or reported.
    assert!(!stdout.contains("batch EDT") && summary.get("batch_edt_ms").is_none(), "{stdout}");
    let (ok, stdout, stderr) =
        edtmap(&["run", "--scene", "planar", "--frames", "4", "--integration", "wavefront", "--out", path(dir.path())]);
    assert!(ok, "{stdout}\n{stderr}");
    let r = report(dir.path());
    assert!(r["stages"]["batch_edt_ms"].is_string(), "{}", r["stages"]);
    for (printed, key) in
        [("occupancy", "ogm_ms"), ("batch EDT", "batch_edt_ms"), ("integration", "integrate_ms"), ("total", "total_ms")]
    {
        let median = r["summary"][key]["median"].as_f64().expect("median");
        let text = format!("{printed} median {median:.2} ms");
        assert!(stdout.contains(&text), "{text:?} not in {stdout}");
    }
}

#[test]
fn eval_on_a_recording_says_there_is_no_occupancy_score() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mcap = dir.path().join("planar.mcap");
    let (ok, stdout, stderr) = edtmap(&["record", "--scene", "planar", "--frames", "3", path(&mcap)]);
    assert!(ok, "{stdout}\n{stderr}");
    let out = dir.path().join("out");
    let config = dir.path().join("planar.toml");
    let (ok, stdout, stderr) =
        edtmap(&["run", "--config", path(&config), "--dataset", path(&mcap), "--eval", "--out", path(&out)]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stderr.contains("--eval") && stderr.contains("ground truth") && stderr.contains("EDT error"), "{stderr}");
    assert!(stdout.contains("EDT vs exact EDT") && !stdout.contains("precision"), "{stdout}");
    let eval = &report(&out)["eval"];
    assert_eq!(eval["occupancy"], false);
    assert_eq!(eval["edt_errors"], true);
}

/// Regression: the help said "Replay a built-in scene" and named two kinds
/// of recording.
#[test]
fn run_help_names_scenes_and_every_kind_of_recording() {
    let (ok, top, _) = edtmap(&["--help"]);
    assert!(ok && top.contains("built-in scene or a recording"), "{top}");
    let (ok, help, _) = edtmap(&["run", "--help"]);
    assert!(ok, "{help}");
    for kind in ["3DMatch", "TUM", "PCD", "PLY", "KITTI", "ROS 1 bag", "MCAP"] {
        assert!(help.contains(kind), "run --help does not name {kind}: {help}");
    }
}

/// `--planar`: the EDT stays in the scan's layer with the same distances
/// there as the 3D EDT of the same scans (queried at the layer's voxel
/// centres), exact against the evaluation's per-layer EDT; `edtmap info`
/// says so; the wavefront mode and the GPU backend are refused by name.
#[test]
fn planar_maps_keep_the_layers_distances_and_nothing_else() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let run = |extra: &[&str], name: &str| {
        let out = d.join(name);
        let save = d.join(format!("{name}.edtmap"));
        let mut args = vec!["run", "--scene", "planar", "--frames", "12", "--eval", "--out", path(&out)];
        args.extend(["--save", path(&save)]);
        args.extend(extra);
        let (ok, stdout, stderr) = edtmap(&args);
        assert!(ok, "{stdout}\n{stderr}");
        assert!(stdout.contains("global max 0.0000 m"), "{stdout}");
        save
    };
    let (flat, deep) = (run(&["--planar"], "planar"), run(&[], "3d"));
    let info = |map: &Path| edtmap(&["info", path(map)]).1;
    let blocks = |text: &str| -> usize {
        let at = text.find(" EDT,").expect("EDT blocks");
        text[..at].rsplit(' ').next().expect("count").parse().expect("a number")
    };
    let (flat_info, deep_info) = (info(&flat), info(&deep));
    assert!(flat_info.contains("planar (distances within each layer)") && !deep_info.contains("planar"), "{flat_info}");
    assert!(blocks(&flat_info) * 3 < blocks(&deep_info), "{flat_info}\n{deep_info}");
    assert!(std::fs::metadata(&flat).expect("saved").len() * 8 < std::fs::metadata(&deep).expect("saved").len());
    // The scan plane is the layer at 0.9-1.0 m: its voxel centres, and the
    // layer above, where only the 3D EDT has distances.
    let points = d.join("points.csv");
    let mut csv = String::new();
    for i in -60..60 {
        for j in -60..60 {
            for z in [0.95, 1.05] {
                csv += &format!("{},{},{z}\n", (f64::from(i) + 0.5) * 0.1, (f64::from(j) + 0.5) * 0.1);
            }
        }
    }
    std::fs::write(&points, csv).expect("points");
    let query = |map: &Path| {
        let (ok, stdout, stderr) = edtmap(&["query", "--points", path(&points), path(map)]);
        assert!(ok, "{stderr}");
        stdout.lines().skip(1).map(|l| l.split(',').map(String::from).collect::<Vec<_>>()).collect::<Vec<_>>()
    };
    let (a, b) = (query(&flat), query(&deep));
    let mut far_above = 0;
    for (p, q) in a.iter().zip(&b) {
        if p[2] == "0.95" {
            assert_eq!((&p[3], &p[4], &p[5], &p[7]), (&q[3], &q[4], &q[5], &q[7]), "{p:?} {q:?}");
            assert_eq!(p[6].trim_start_matches('-'), "0.000000", "no z gradient: {p:?}");
        } else {
            assert_eq!(p[3], "2.000000", "nothing above the layer: {p:?}");
            far_above += usize::from(q[3] != "2.000000");
        }
    }
    assert!(far_above > 1000, "the 3D EDT reaches above the layer at {far_above} points");
    let (ok, _, stderr) =
        edtmap(&["run", "--scene", "planar", "--frames", "1", "--planar", "--integration", "wavefront"]);
    assert!(!ok && stderr.contains("planar") && stderr.contains("exact"), "{stderr}");
    let (ok, _, stderr) = edtmap(&["run", "--scene", "planar", "--frames", "1", "--planar", "--backend", "gpu"]);
    assert!(!ok && stderr.contains("--backend gpu") && stderr.contains("planar") && stderr.contains("CPU"), "{stderr}");
}

#[test]
fn a_scene_of_no_frames_names_the_config_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = dir.path().join("zero.toml");
    let shipped = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/planar.toml"))
        .expect("planar.toml");
    std::fs::write(&config, shipped.replace("[scene]\n", "[scene]\nframes = 0\n")).expect("write");
    let (ok, _, stderr) = edtmap(&["run", "--config", path(&config), "--out", path(dir.path())]);
    assert!(!ok && stderr.contains("[scene] frames = 0") && !stderr.contains("--frames"), "{stderr}");
}

/// Each frame says how many threads it ran on: the whole pool with
/// `--fixed-threads`, never more than the pool without it; the saved map
/// is the same either way.
#[test]
fn each_frame_reports_the_threads_it_ran_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut maps = Vec::new();
    for fixed in [true, false] {
        let out = dir.path().join(if fixed { "fixed" } else { "follow" });
        let map = out.with_extension("edtmap");
        let mut args = vec!["run", "--scene", "room", "--frames", "6", "--out", path(&out), "--save", path(&map)];
        if fixed {
            args.push("--fixed-threads");
        }
        let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
            .args(&args)
            .env("RAYON_NUM_THREADS", "3")
            .output()
            .expect("edtmap runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r = report(&out);
        assert_eq!(r["threads"], 3);
        let frames = r["frames"].as_array().expect("frames");
        assert_eq!(frames.len(), 6);
        for f in frames {
            let t = f["threads"].as_f64().expect("threads");
            if fixed {
                assert_eq!(t, 3.0, "{f}");
            } else {
                assert!([1.0, 2.0, 3.0].contains(&t), "{f}");
            }
        }
        maps.push(std::fs::read(&map).expect("map"));
    }
    assert!(maps[0] == maps[1], "the thread count changed the map");
}
