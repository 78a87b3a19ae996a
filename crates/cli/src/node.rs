//! `edtmap node`: the mapper live on ROS 2 until SIGINT (or `--frames`,
//! `--duration-s`), then the map saved when asked.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use edtmap::config::Config;
use edtmap_node as node;
use edtmap_ros::poses::SensorMessage;
use node::config::RosSection;

/// Arguments of `edtmap node`.
#[derive(Args, Debug, Clone)]
pub(crate) struct NodeArgs {
    /// The config: `[sensor]`, `[occupancy]`, `[global]` as for `edtmap
    /// run`, and `[ros]` for topics, frames and outputs.
    #[arg(long)]
    config: PathBuf,
    /// A saved map to go on from.
    #[arg(long)]
    map: Option<PathBuf>,
    /// Save the map here when the node stops (replaces `[ros]
    /// save_on_exit`).
    #[arg(long)]
    save: Option<PathBuf>,
    /// Stop after this many frames are integrated.
    #[arg(long)]
    frames: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long)]
    duration_s: Option<f64>,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// SIGINT and SIGTERM end the node cleanly (the map saved first).
fn catch_signals() {
    let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, handler);
        libc::signal(libc::SIGTERM, handler);
    }
}

pub(crate) fn run(args: &NodeArgs) -> Result<()> {
    let text = edtmap::config::read(&args.config)?;
    let origin = args.config.display().to_string();
    let config = Config::parse(&text, &origin)?;
    let mut ros = RosSection::parse(&text, &origin)?;
    if let Some(save) = &args.save {
        edtmap_io::files::check_output(save)?;
        ros.save_on_exit = Some(save.clone());
    }
    if let Some(d) = args.duration_s {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration-s {d}: must be a positive number of seconds");
        }
    }
    let map = match &args.map {
        Some(path) => Some(edtmap::load_map(path).with_context(|| format!("--map {}", path.display()))?),
        None => None,
    };
    let mapper =
        node::mapper(&config, map, crate::memory::max_bytes()).with_context(|| args.config.display().to_string())?;
    catch_signals();
    let handle = node::start(&config, &ros, mapper).with_context(|| args.config.display().to_string())?;
    let started = Instant::now();
    let mut last_report = Instant::now();
    let reason = loop {
        std::thread::sleep(Duration::from_millis(20));
        let stats = handle.stats();
        if STOP.load(Ordering::SeqCst) {
            break "interrupted";
        }
        if args.frames.is_some_and(|n| stats.integrated >= n) {
            break "--frames reached";
        }
        if args.duration_s.is_some_and(|d| started.elapsed().as_secs_f64() >= d) {
            break "--duration-s reached";
        }
        if handle.is_finished() {
            break "the mapping thread ended";
        }
        if last_report.elapsed() >= Duration::from_secs(10) {
            last_report = Instant::now();
            tracing::info!(
                "{} frames integrated, {} received, {} dropped, skipped {:?}, {} requests",
                stats.integrated,
                stats.received,
                stats.dropped,
                stats.skipped,
                stats.requests
            );
        }
    };
    let stats = handle.stop()?;
    outln!(
        "edtmap node stopped ({reason}): {} frames integrated of {} received, {} dropped as newer ones came, {} skipped {:?}, {} service requests",
        stats.integrated,
        stats.received,
        stats.dropped,
        stats.skipped.values().sum::<u64>(),
        stats.skipped,
        stats.requests
    );
    if let Some(path) = &ros.save_on_exit {
        outln!("saved the map to {}", path.display());
    }
    if stats.sensors.len() > 1 {
        for s in &stats.sensors {
            outln!(
                "  {} on {}: {} frames integrated of {} received, {} dropped",
                s.name,
                s.topic,
                s.integrated,
                s.received,
                s.dropped
            );
        }
    }
    if stats.integrated == 0 {
        let wanted: Vec<String> = stats
            .sensors
            .iter()
            .zip(config.sensors())
            .map(|(s, section)| {
                let message = SensorMessage::of(section.kind).unwrap_or(SensorMessage::PointCloud2);
                format!("{} carries {}", s.topic, message.ros_type())
            })
            .collect();
        bail!(
            "no frame was integrated in {:.1} s: check that {} and that poses come on {} (`ros2 topic list`, ROS_DOMAIN_ID, [ros] localhost_only)",
            started.elapsed().as_secs_f64(),
            wanted.join(" and "),
            ros.pose_topic
        );
    }
    Ok(())
}
