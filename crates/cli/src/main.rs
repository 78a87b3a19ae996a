//! The `edtmap` command-line program.

#[macro_use]
mod output;
mod backend;
mod demo;
mod edt;
mod interrupt;
mod memory;
mod node;
mod pictures;
mod query;
mod record;
mod report;
mod run;
mod scenes;
mod sections;
mod source;
mod timing;

use std::io::Write;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Volumetric mapping for motion planning: occupancy and exact Euclidean
/// distance transforms.
#[derive(Parser)]
#[command(name = "edtmap", version, about)]
struct Cli {
    /// Log more to stderr: -v progress of each stage, -vv every frame.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Most memory a job may use (8G, 512M, bytes); default: what the
    /// system has free, within the process's address-space limit.
    #[arg(long, global = true, value_name = "SIZE", value_parser = edtmap::memory::parse_size)]
    max_memory: Option<u64>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in demonstration and write pictures to ./edtmap-out/.
    Demo(demo::DemoArgs),
    /// Exact Euclidean distance transform of a 2D or 3D .npy grid.
    Edt(edt::EdtArgs),
    /// Map a built-in scene or a recording (3DMatch, TUM, PCD, PLY or KITTI folder; ROS 1 bag; MCAP); writes report.json and pictures.
    Run(run::RunArgs),
    /// Write a built-in scene as a ROS 1 bag or ROS 2 MCAP file, with the config that replays it.
    Record(record::RecordArgs),
    /// Map live on ROS 2: sensor and pose topics in; ESDF clouds, slices and distance services out.
    Node(node::NodeArgs),
    /// Distance, gradient and state at points (CSV) from a saved map.
    Query(query::QueryArgs),
    /// A dense box of distances from a saved map, as .npy; or, to OUT.yaml, a 2D map for ROS navigation (map_server).
    Export(query::ExportArgs),
    /// What a saved map holds: size, extent, parameters.
    Info(query::InfoArgs),
    /// Top views of a saved map as PNG: occupancy and distance at a height, their projection through the heights.
    Picture(pictures::PictureArgs),
}

/// Logs to stderr: warnings by default (frames skipped, recordings cut
/// short), `-v` information, `-vv` every frame, `-vvv` everything.
fn init_logs(verbose: u8) {
    use tracing_subscriber::filter::LevelFilter;
    let level = match verbose {
        0 => LevelFilter::WARN,
        1 => LevelFilter::INFO,
        2 => LevelFilter::DEBUG,
        _ => LevelFilter::TRACE,
    };
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .with_target(false)
        .without_time()
        .init();
}

/// Runs `job` on a thread of rayon's pool, with the main thread's stack
/// size, so that the stages' parallel loops start from a worker of the
/// pool instead of being handed to the pool and waited for, loop by loop:
/// on a 720-beam planar scan at 0.1 m, a fifth of a frame's time.
fn on_pool<T: Send>(job: impl FnOnce() -> T + Send) -> T {
    // Only a pool built already (none is) makes this fail; then the
    // default pool serves.
    let _ = rayon::ThreadPoolBuilder::new().stack_size(MAIN_STACK_BYTES).build_global();
    rayon::scope(|_| job())
}

/// The main thread's stack on Linux, bytes: what the commands' code was
/// written against.
pub(crate) const MAIN_STACK_BYTES: usize = 8 << 20;

/// Keeps the memory a command frees for its next use (glibc only). glibc
/// hands a block of 128 KiB or more back to the system as soon as it is
/// freed (an `mmap` of its own, or the top of the heap beyond 128 KiB), so
/// a buffer a stage allocates and frees every frame is faulted in again
/// every frame, a page at a time: a depth camera's per-pixel thresholds,
/// 1.2 MB at 640 × 480, cost 0.5 ms a frame that way. With blocks up to
/// 32 MiB served from the heap and the heap trimmed only beyond 1 GiB
/// free, the pages stay; the peak memory is the same.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` sets two thresholds of glibc's allocator; it takes
    // the allocator's lock and changes nothing else.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    init_logs(cli.verbose);
    memory::set_max(cli.max_memory);
    // The node's threads wait on the network; a worker of the pool must not.
    let on_network = matches!(cli.command, Command::Node(_));
    let command = move || match cli.command {
        Command::Demo(args) => demo::run(&args),
        Command::Edt(args) => edt::run(&args),
        Command::Run(args) => run::run(&args),
        Command::Record(args) => record::record(&args),
        Command::Node(args) => node::run(&args),
        Command::Query(args) => query::query(&args),
        Command::Export(args) => query::export(&args),
        Command::Info(args) => query::info(&args),
        Command::Picture(args) => pictures::picture(&args),
    };
    let result = if on_network { command() } else { on_pool(command) };
    let result = match (result, output::finish()) {
        (Ok(()), Some(e)) => Err(anyhow::anyhow!("cannot write to standard output: {e}")),
        (result, _) => result,
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => match e.downcast_ref::<interrupt::Interrupted>() {
            Some(stop) => {
                let _ = writeln!(std::io::stderr(), "edtmap: {stop}");
                ExitCode::from(stop.exit_code())
            }
            None => {
                // Stderr may be closed too; there is nowhere left to say it.
                let _ = writeln!(std::io::stderr(), "edtmap: error: {e:#}");
                ExitCode::FAILURE
            }
        },
    }
}
