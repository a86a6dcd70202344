//! The commands of `parallax`, one module each: its arguments (a clap
//! `Args`) and its `run`. `main` parses a [`Command`] and calls [`run`].

mod args;
pub mod bench;
pub mod calibrate;
pub mod display_gen;
pub mod import;
pub mod info;
pub mod quilt;
pub mod render;
pub mod serve;
pub mod simulate;
pub mod synth;
pub mod tf;

use anyhow::Result;
use clap::Subcommand;

#[derive(Subcommand)]
pub enum Command {
    Synth(synth::Args),
    Import(import::Args),
    Render(render::Args),
    Serve(serve::Args),
    Bench(bench::Args),
    Tf(tf::Args),
    DisplayGen(display_gen::Args),
    Simulate(simulate::Args),
    Quilt(quilt::Args),
    Info(info::Args),
    Calibrate(calibrate::Args),
}

/// Runs one command.
pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Synth(a) => synth::run(a),
        Command::Import(a) => import::run(a),
        Command::Render(a) => render::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Tf(a) => tf::run(a),
        Command::DisplayGen(a) => display_gen::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Quilt(a) => quilt::run(a),
        Command::Info(a) => info::run(a),
        Command::Calibrate(a) => calibrate::run(a),
    }
}
