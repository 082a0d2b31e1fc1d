use formats::mres::MresFile;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let f = MresFile::open(std::path::Path::new(&a[1])).unwrap();
    for c in a[2..].iter().map(|s| s.parse::<usize>().unwrap()) {
        let ci = &f.clusters[c];
        let own = if ci.own_group == u32::MAX { None } else { Some(f.groups[ci.own_group as usize]) };
        println!("cluster {c}: {:?}\n  group {:?}\n  own {:?}", ci, f.groups[ci.group as usize], own);
    }
}
