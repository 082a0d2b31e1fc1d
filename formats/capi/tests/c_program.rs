//! Builds `tests/c/load.c` with the system C compiler against the static library and runs it
//! on a file made here: what it prints (read through the C ABI, prefix first, page by page)
//! must equal what the Rust reader says, and damaged files must give the right status codes.
//! Also compiles the header as C++ and calls through it.

mod common;

use mres_format::records::HeaderRecord;
use mres_format::{uniform_cut, MresFile, HEADER_SIZE};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// This crate's folder for built programs and test files, in cargo's scratch space.
fn scratch() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mres-capi");
    std::fs::create_dir_all(&dir).expect("creates the scratch folder");
    dir
}

/// A library cargo built for this test run (`libmres.a` or `libmres.so`). Cargo builds every
/// crate type of the library for the integration tests, into `target/<profile>/deps/` beside
/// the test binary; the copy one folder up is refreshed only by `cargo build`, so it may be
/// stale.
fn built_lib(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let lib = exe.parent().expect("target/<profile>/deps").join(name);
    assert!(lib.is_file(), "{} not found: cargo builds it with the test", lib.display());
    lib
}

/// Compiles `sources` (C, or C++ when `cxx`) into an executable linked with `lib` (a path
/// from [`built_lib`]).
fn compile(name: &str, sources: &[PathBuf], cxx: bool, lib: &Path) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let exe = scratch().join(name);
    let compiler = match cxx {
        true => std::env::var("CXX").unwrap_or_else(|_| "c++".into()),
        false => std::env::var("CC").unwrap_or_else(|_| "cc".into()),
    };
    let standard = if cxx { "-std=c++17" } else { "-std=c11" };
    let rpath = format!("-Wl,-rpath,{}", lib.parent().expect("the library's folder").display());
    let output = Command::new(&compiler)
        .args([standard, "-Wall", "-Wextra", "-Werror", "-pedantic", "-ffp-contract=off", "-O1"])
        .arg("-I")
        .arg(dir.join("include"))
        .args(sources)
        .arg(lib)
        // What the Rust standard library needs from the system when linked statically, and
        // where the shared library is found at run time.
        .args(["-lstdc++", "-lpthread", "-ldl", "-lm", &rpath, "-o"])
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("running the C compiler `{compiler}`: {e}"));
    assert!(output.status.success(), "{compiler} failed:\n{}", String::from_utf8_lossy(&output.stderr));
    exe
}

fn load_c_source() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/c/load.c")
}

/// `tests/c/load.c` linked with the static library, compiled once for all tests (they run in
/// parallel).
fn load_c() -> &'static Path {
    static EXE: OnceLock<PathBuf> = OnceLock::new();
    EXE.get_or_init(|| compile("load", &[load_c_source()], false, &built_lib("libmres.a")))
}

fn run(exe: &Path, file: &[u8], name: &str) -> Output {
    let path = scratch().join(name);
    std::fs::write(&path, file).expect("writes the test file");
    Command::new(exe).arg(&path).output().expect("runs the C program")
}

/// The summary the C program must print, from the Rust reader.
fn expected(bytes: &[u8]) -> BTreeMap<String, String> {
    let file = MresFile::parse(bytes.to_vec()).expect("parses");
    let triangles: u64 = file.clusters.iter().map(|c| u64::from(c.triangle_count)).sum();
    let vertices: u64 = file.clusters.iter().map(|c| u64::from(c.vertex_count)).sum();
    let gpu_bytes: u64 = file.pages.iter().map(|p| u64::from(p.raw_size)).sum();
    let dependencies: usize = file.pages.iter().map(|p| p.dependencies.len()).sum();
    let index = mres_format::MresIndex::parse(bytes).expect("parses");
    let sources: usize = (0..file.pages.len() as u32).map(|p| index.page_sources(p).expect("a page").len()).sum();
    let figures = [
        ("pages", file.pages.len().to_string()),
        ("clusters", file.clusters.len().to_string()),
        ("triangles", triangles.to_string()),
        ("vertices", vertices.to_string()),
        ("gpu_bytes", gpu_bytes.to_string()),
        ("dependencies", dependencies.to_string()),
        ("sources", sources.to_string()),
        ("level0_clusters", uniform_cut(&file.groups, &file.clusters, 0.0).len().to_string()),
        ("root_clusters", uniform_cut(&file.groups, &file.clusters, f32::MAX).len().to_string()),
        // The header is read twice (once alone, once with the prefix), every page once.
        ("read_bytes", (HEADER_SIZE + bytes.len()).to_string()),
        ("hash", format!("{:016x}", common::hash(&file))),
    ];
    figures.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

fn summary(output: &Output) -> BTreeMap<String, String> {
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "load failed: {}\n{stdout}", String::from_utf8_lossy(&output.stderr));
    stdout
        .lines()
        .map(|line| {
            let (key, value) = line.split_once(' ').expect("`key value` lines");
            (key.to_string(), value.to_string())
        })
        .collect()
}

#[test]
fn c_program_streams_the_file_and_agrees_with_the_rust_reader() {
    let exe = load_c();
    let bytes = common::file();
    let want = expected(&bytes);
    // The file exercises the streaming: several pages, with dependencies between them.
    assert!(want["pages"].parse::<u32>().unwrap() >= 3, "{want:?}");
    assert!(want["dependencies"] != "0" && want["sources"] != "0", "{want:?}");
    assert_eq!(summary(&run(exe, &bytes, "synthetic.mres")), want);

    // The sample DAG: one page, every attribute.
    let sample = mres_format::write_mres(&mres_format::Dag::sample(), 3).expect("writes");
    assert_eq!(summary(&run(exe, &sample, "sample.mres")), expected(&sample));

    // Layout pages (docs/FORMAT.md §4.4): no sources, the same GPU layouts (the hash).
    let layout = mres_format::write_mres_with(&common::dag(), 3, mres_format::PageCoding::Layout).expect("writes");
    let got = summary(&run(exe, &layout, "layout.mres"));
    assert_eq!(got, expected(&layout));
    assert_eq!((got["sources"].as_str(), &got["hash"]), ("0", &want["hash"]), "{got:?}");
}

/// Runs the C program on `bytes` and returns the status name it failed with.
fn failure(exe: &Path, bytes: &[u8], name: &str) -> String {
    let output = run(exe, bytes, name);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(1), "expected a failed call, got: {stderr}");
    let rest = stderr.strip_prefix("error: ").unwrap_or_else(|| panic!("unexpected stderr: {stderr}"));
    rest.split(':').next().unwrap_or_default().to_string()
}

#[test]
fn c_program_reports_damage_with_status_codes() {
    let exe = load_c();
    let bytes = common::file();
    let index = mres_format::MresIndex::parse(&bytes).expect("parses");
    let prefix_len = index.pages[0].offset as usize;

    // The file ends inside the prefix: the C program's read comes up short.
    assert_eq!(failure(exe, &bytes[..prefix_len - 1], "short.mres"), "MRES_ERR_TRUNCATED");
    // The file ends inside the fixed header.
    assert_eq!(failure(exe, &bytes[..HEADER_SIZE - 1], "tiny.mres"), "MRES_ERR_TRUNCATED");

    // One flipped byte in page 1's compressed bytes.
    let mut flipped = bytes.clone();
    flipped[index.page_range(1).unwrap().start as usize + 5] ^= 0x40;
    assert_eq!(failure(exe, &flipped, "flipped.mres"), "MRES_ERR_CHECKSUM");

    // One flipped byte in the hierarchy (the prefix's checksum covers it).
    let mut flipped = bytes.clone();
    flipped[HEADER_SIZE + 3] ^= 1;
    assert_eq!(failure(exe, &flipped, "hierarchy.mres"), "MRES_ERR_CHECKSUM");

    // The file's last page cut short.
    assert_eq!(failure(exe, &bytes[..bytes.len() - 1], "cut.mres"), "MRES_ERR_PAGE_LENGTH");

    // A future version.
    let mut future = bytes.clone();
    future[HeaderRecord::VERSION..][..4].copy_from_slice(&(mres_format::VERSION + 1).to_le_bytes());
    assert_eq!(failure(exe, &future, "future.mres"), "MRES_ERR_VERSION");
}

#[test]
fn header_compiles_as_cpp_and_links() {
    let source = scratch().join("header_check.cpp");
    std::fs::write(
        &source,
        "#include \"mres.h\"\n\
         #include <cstring>\n\
         int main() {\n\
             MresIndex* index = reinterpret_cast<MresIndex*>(1);\n\
             if (mres_index_open(nullptr, 0, &index) != MRES_ERR_TRUNCATED || index != nullptr) return 1;\n\
             if (std::strncmp(mres_last_error_message(), \"mres_index_open: truncated\", 26) != 0) return 2;\n\
             return mres_index_open(nullptr, 1, &index) == MRES_ERR_ARG ? 0 : 3;\n\
         }\n",
    )
    .expect("writes the C++ source");
    let exe = compile("header_check", &[source], true, &built_lib("libmres.a"));
    let status = Command::new(&exe).status().expect("runs the C++ program");
    assert_eq!(status.code(), Some(0));
}

#[test]
fn shared_library_exports_the_header_functions_and_works() {
    let so = built_lib("libmres.so");
    let nm = Command::new("nm").args(["-D", "--defined-only"]).arg(&so).output().expect("runs nm");
    assert!(nm.status.success(), "nm failed");
    let exported: BTreeSet<String> = String::from_utf8_lossy(&nm.stdout)
        .lines()
        .filter_map(|line| line.split_whitespace().nth(2))
        .map(str::to_string)
        .collect();
    let header = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("include/mres.h")).unwrap();
    // Every identifier that stands before a `(` (declarations, and calls in the comments).
    let declared: BTreeSet<String> = header
        .split('(')
        .filter_map(|before| before.rsplit(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).next())
        .filter(|name| name.starts_with("mres_"))
        .map(str::to_string)
        .collect();
    assert!(declared.len() >= 20, "{declared:?}");
    assert_eq!(exported, declared, "the shared library exports exactly the header's functions");

    let exe = compile("load_shared", &[load_c_source()], false, &so);
    let sample = mres_format::write_mres(&mres_format::Dag::sample(), 3).expect("writes");
    assert_eq!(summary(&run(&exe, &sample, "sample_shared.mres")), expected(&sample));
}
