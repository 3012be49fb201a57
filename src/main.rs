//! The `radcache` binary: a thin shell over [`radcache::cli`].

fn main() -> std::process::ExitCode {
    radcache::cli::main()
}
