#!/usr/bin/env python3
"""Checks the declared rust-version of a Cargo workspace against what it depends on.

    ci/msrv.py MANIFEST...

The machines that run CI have one Rust toolchain (newer than the declared minimum) and cannot
fetch another, so "builds with the declared rust-version" is checked in two halves: this script
fails if any package in the workspace's resolved dependency graph (Cargo.lock) declares a
`rust-version` above the workspace's own, and `cargo clippy -- -D warnings` (ci/lint) fails on
any standard-library item newer than it (clippy's `incompatible_msrv` lint reads the same field).
"""
import json
import subprocess
import sys


def version(text):
    parts = [int(part) for part in text.split("+")[0].split(".")[:3]]
    return tuple(parts + [0] * (3 - len(parts)))


def check(manifest):
    meta = json.loads(subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--locked", "--manifest-path", manifest],
        check=True, capture_output=True, text=True).stdout)
    members = set(meta["workspace_members"])
    resolved = {node["id"] for node in meta["resolve"]["nodes"]}
    packages = [p for p in meta["packages"] if p["id"] in resolved]
    declared = {p["rust_version"] for p in packages if p["id"] in members}
    if len(declared) != 1 or None in declared:
        print(f"{manifest}: workspace members must declare one rust-version, found {sorted(map(str, declared))}")
        return False
    ours = declared.pop()
    newer = [(p["name"], p["version"], p["rust_version"]) for p in packages
             if p["id"] not in members and p.get("rust_version") and version(p["rust_version"]) > version(ours)]
    for name, ver, rv in sorted(newer):
        print(f"{manifest}: {name} {ver} needs rust {rv}, above the declared rust-version {ours}")
    if not newer:
        print(f"{manifest}: rust-version {ours}; no dependency declares a newer one ({len(packages)} packages)")
    return not newer


if __name__ == "__main__":
    results = [check(m) for m in sys.argv[1:]]
    sys.exit(0 if results and all(results) else 1)
