//! `datagen`: generate randomized scenes, render datasets (sharded, kill-safe), assemble and
//! check manifests, and draw contact sheets. See `docs/datagen.md`.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use datagen::config::Config;
use datagen::families::{generate, scene_list};
use datagen::scene::write_scene_files;
use std::path::PathBuf;

/// Dataset generation for multi-level SPPM post-reconstruction.
#[derive(Debug, Parser)]
#[command(name = "datagen", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write every scene of a config as Mitsuba 3 XML + PLY into OUT/<scene-id>/.
    Scenes {
        /// Dataset config (TOML), e.g. configs/datagen/small.toml.
        #[arg(long)]
        config: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
}

fn main() {
    if let Err(e) = run(Cli::parse()) {
        eprintln!("datagen: error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Scenes { config, out } => {
            let config = Config::load(&config)?;
            let list = scene_list(&config);
            for (index, (id, _)) in list.iter().enumerate() {
                let scene = generate(&config, index);
                let xml = write_scene_files(&scene, &out.join(id))
                    .with_context(|| format!("writing scene {id}"))?;
                println!("{}", xml.display());
            }
            Ok(())
        }
    }
}
