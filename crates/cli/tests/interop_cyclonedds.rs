//! `edtmap node` against Cyclone DDS, the DDS of ROS 2's rmw_cyclonedds_cpp:
//! runs the Python interop tests in `tests/interop` (pytest, with the
//! `cyclonedds` package as the ROS 2 side) on this build's binary.
//!
//! The Python interpreter is `EDTMAP_INTEROP_PYTHON` when set (one with
//! `tests/interop/requirements.txt` installed); otherwise a virtual
//! environment in `target/interop-venv`, made with `python3 -m venv` and
//! pip the first time (that needs python3 with its venv module, and the
//! network or a wheel cache). When that cannot be had the test fails and
//! says what to install, unless `EDTMAP_SKIP_INTEROP=1`, which skips it.
#![cfg(unix)]

use std::ffi::OsStr;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The whole pytest run.
const PYTEST_LIMIT: Duration = Duration::from_secs(300);
/// Making the virtual environment, and pip installing into it.
const SETUP_LIMIT: Duration = Duration::from_secs(600);

/// What a command did.
struct Done {
    status: ExitStatus,
    stdout: String,
    stderr: String,
}

impl Done {
    fn output(&self) -> String {
        format!("--- stdout ---\n{}\n--- stderr ---\n{}", self.stdout, self.stderr)
    }
}

/// Runs `cmd` in a process group of its own with its output captured;
/// after `limit` the whole group is killed (pytest and the node it started).
fn run_limited(mut cmd: Command, limit: Duration) -> Result<Done, String> {
    let shown = format!("{cmd:?}");
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .map_err(|e| format!("{shown} did not start: {e}"))?;
    let read = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut bytes);
            }
            String::from_utf8_lossy(&bytes).into_owned()
        })
    };
    let out = read(child.stdout.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let err = read(child.stderr.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > limit => {
                // SAFETY: kill(2) on the process group this function made.
                unsafe { libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL) };
                let _ = child.wait();
                let (stdout, stderr) = (out.join().unwrap_or_default(), err.join().unwrap_or_default());
                return Err(format!("{shown} still ran after {limit:?} and was killed\n--- stdout ---\n{stdout}\n--- stderr ---\n{stderr}"));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => return Err(format!("waiting for {shown}: {e}")),
        }
    };
    Ok(Done { status, stdout: out.join().unwrap_or_default(), stderr: err.join().unwrap_or_default() })
}

fn command<S: AsRef<OsStr>>(program: impl AsRef<OsStr>, args: &[S]) -> Command {
    let mut cmd = Command::new(program);
    cmd.args(args);
    cmd
}

/// Whether `python` has every `name==version` of the requirements file.
fn has_requirements(python: &Path, requirements: &Path) -> bool {
    // A missing package raises, and exits non-zero too.
    let check = "import sys, importlib.metadata as m\n\
                 pins = [line.split('#')[0].strip().partition('==') for line in open(sys.argv[1])]\n\
                 sys.exit(any(name and m.version(name.strip()) != want.strip() for name, _, want in pins))\n";
    run_limited(
        command(python, &[OsStr::new("-c"), OsStr::new(check), requirements.as_os_str()]),
        Duration::from_secs(60),
    )
    .is_ok_and(|d| d.status.success())
}

/// The interpreter to run pytest with, or why there is none.
fn python(root: &Path) -> Result<PathBuf, String> {
    if let Some(p) = std::env::var_os("EDTMAP_INTEROP_PYTHON") {
        return Ok(PathBuf::from(p));
    }
    let requirements = root.join("tests/interop/requirements.txt");
    let venv = root.join("target/interop-venv");
    let python = venv.join("bin/python");
    if python.exists() && has_requirements(&python, &requirements) {
        return Ok(python);
    }
    let made = run_limited(command("python3", &[OsStr::new("-m"), OsStr::new("venv"), venv.as_os_str()]), SETUP_LIMIT)
        .map_err(|e| format!("could not run python3: {e}\ninstall Python 3 with its venv module (Debian/Ubuntu: apt-get install python3 python3-venv)"))?;
    if !made.status.success() {
        return Err(format!(
            "`python3 -m venv {}` failed; install Python 3's venv module (Debian/Ubuntu: apt-get install python3-venv)\n{}",
            venv.display(),
            made.output()
        ));
    }
    let pip = [
        OsStr::new("-m"),
        OsStr::new("pip"),
        OsStr::new("install"),
        OsStr::new("--disable-pip-version-check"),
        OsStr::new("-q"),
        OsStr::new("-r"),
        requirements.as_os_str(),
    ];
    let installed = run_limited(command(&python, &pip), SETUP_LIMIT)?;
    if !installed.status.success() || !has_requirements(&python, &requirements) {
        return Err(format!(
            "`{} -m pip install -r {}` failed (no network?); install those packages into a Python 3 environment and set EDTMAP_INTEROP_PYTHON to its python\n{}",
            python.display(),
            requirements.display(),
            installed.output()
        ));
    }
    Ok(python)
}

#[test]
fn the_node_interoperates_with_cyclonedds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let root = root.canonicalize().unwrap_or(root);
    let python = match python(&root) {
        Ok(p) => p,
        Err(why) if std::env::var("EDTMAP_SKIP_INTEROP").is_ok_and(|v| v == "1") => {
            eprintln!("skipping the Cyclone DDS interop test (EDTMAP_SKIP_INTEROP=1): {why}");
            return;
        }
        Err(why) => panic!("the Cyclone DDS interop test needs Python with tests/interop/requirements.txt (or EDTMAP_SKIP_INTEROP=1 to skip it):\n{why}"),
    };
    let mut cmd = command(&python, &["-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/interop"]);
    cmd.current_dir(&root).env("EDTMAP_BIN", env!("CARGO_BIN_EXE_edtmap")).env("PYTHONDONTWRITEBYTECODE", "1");
    let started = Instant::now();
    let done = run_limited(cmd, PYTEST_LIMIT).unwrap_or_else(|e| panic!("pytest with {}: {e}", python.display()));
    assert!(
        done.status.success(),
        "the interop tests failed ({}), {:.1} s:\n{}",
        done.status,
        started.elapsed().as_secs_f64(),
        done.output()
    );
    eprintln!(
        "interop tests passed in {:.1} s: {}",
        started.elapsed().as_secs_f64(),
        done.stdout.lines().last().unwrap_or_default()
    );
}
