fn main() -> std::process::ExitCode {
    kinepost::cli::main()
}
