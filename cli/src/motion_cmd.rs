use anyhow::Result;
use clap::{Args, Subcommand};
use lhm_sim::motion::{default_dir, library};
use std::path::PathBuf;

#[derive(Args)]
pub struct MotionArgs {
    #[command(subcommand)]
    command: MotionCommand,
}

#[derive(Subcommand)]
enum MotionCommand {
    /// The installed reference clips with their lengths (install: scripts/install-motions).
    List {
        /// Clip cache (default: $LHM_MOTION_DIR, else ~/.cache/lhm/motions).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
}

pub fn run(args: MotionArgs) -> Result<()> {
    match args.command {
        MotionCommand::List { dir } => {
            let dir = dir.unwrap_or_else(default_dir);
            let clips = library::list(&dir)?;
            println!("{} clips in {}", clips.len(), dir.display());
            for c in clips {
                println!(
                    "  {:<22} {:<10} {:>4} frames  {:>5.2} s",
                    c.name,
                    format!("{:?}", c.source),
                    c.frames,
                    c.duration_s
                );
            }
            Ok(())
        }
    }
}
