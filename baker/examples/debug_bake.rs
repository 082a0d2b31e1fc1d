fn main() {
    let path = std::env::args().nth(1).unwrap();
    let b = baker::bake::bake_file(std::path::Path::new(&path), &baker::BakeSettings::default()).unwrap();
    println!("{:?}", b.stats);
}
