fn main() {
    std::process::exit(topspin::cli::main());
}
