//! The `edtmap` command-line program.

mod backend;
mod demo;
mod edt;
mod memory;
mod pictures;
mod query;
mod report;
mod run;
mod scenes;
mod timing;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Volumetric mapping for motion planning: occupancy and exact Euclidean
/// distance transforms.
#[derive(Parser)]
#[command(name = "edtmap", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in demonstration and write pictures to ./edtmap-out/.
    Demo(demo::DemoArgs),
    /// Exact Euclidean distance transform of a 2D or 3D .npy grid.
    Edt(edt::EdtArgs),
    /// Replay a built-in scene through the mapping pipeline; writes report.json and pictures.
    Run(run::RunArgs),
    /// Distance, gradient and state at points (CSV) from a saved map.
    Query(query::QueryArgs),
    /// A dense box of distances from a saved map, as .npy.
    Export(query::ExportArgs),
    /// What a saved map holds: size, extent, parameters.
    Info(query::InfoArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => demo::run(&args),
        Command::Edt(args) => edt::run(&args),
        Command::Run(args) => run::run(&args),
        Command::Query(args) => query::query(&args),
        Command::Export(args) => query::export(&args),
        Command::Info(args) => query::info(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("edtmap: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
