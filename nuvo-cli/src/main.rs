//! The `nuvo` command line.
fn main() {
    println!("nuvo: work in progress");
}
