//! Converts real `.mres` files into seeds for the `mres_reader_resealed` fuzz target
//! (pages decompressed, checksums zeroed): `cargo run --example unseal -- IN.mres OUT`.
//! With `--check`, also verifies that sealing the result gives a file that parses and decodes.

#[path = "../fuzz_targets/reseal.rs"]
mod reseal;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let check = args.iter().any(|a| a == "--check");
    let paths: Vec<&String> = args.iter().filter(|a| *a != "--check").collect();
    let [input, output] = paths[..] else {
        eprintln!("usage: unseal [--check] IN.mres OUT");
        std::process::exit(2);
    };
    let bytes = std::fs::read(input).expect("read input");
    let unsealed = reseal::unseal(&bytes).expect("input is not a well-formed .mres file");
    if check {
        let file = mres_format::MresFile::parse(reseal::seal(&unsealed)).expect("resealed file parses");
        let original = mres_format::MresFile::parse(bytes).expect("original parses");
        assert_eq!(file.decode_all().expect("resealed decodes"), original.decode_all().expect("original decodes"));
    }
    std::fs::write(output, &unsealed).expect("write output");
    eprintln!(
        "{input}: {} bytes -> {output}: {} bytes unsealed",
        std::fs::metadata(input).unwrap().len(),
        unsealed.len()
    );
}
