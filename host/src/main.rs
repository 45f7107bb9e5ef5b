//! `jointid`: command-line entry point.
fn main() {
    println!("jointid");
}
