//! The `kinepost` binary: the command line is here and only here (the library knows none of it).

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
