//! Bakes one mesh with the default settings and prints its figures, stage timings included:
//! `cargo run --release -p mres-cli --example bake_stats -- MESH`.
fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: bake_stats MESH");
        std::process::exit(2);
    };
    match mres_build::bake::bake_file(std::path::Path::new(&path), &mres_build::BakeSettings::default(), &|_| {}) {
        Ok(b) => println!("{:#?}", b.stats),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}
