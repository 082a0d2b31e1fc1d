"""Tests of scripts/check_mres.py, the independent .mres checker.

Small meshes are generated and baked with the Rust tools (`mres generate`,
`bake-all`); the checker must pass them, agree with `mres validate --json`, and
catch corruptions made here byte by byte. Skipped when the Rust tools are not
built (cargo build --release -p mres-cli).

Run: .venv/bin/pytest scripts/test_check_mres.py -q
"""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import blake3
import pytest
import zstandard

ROOT = Path(__file__).resolve().parent.parent
CHECKER = ROOT / "scripts" / "check_mres.py"
MRES = ROOT / "target" / "release" / "mres"
BAKE_ALL = ROOT / "target" / "release" / "bake-all"

# cheap settings: the corruptions are caught by the structural checks and the
# uniform cuts; a few random cuts keep that path exercised
FAST = ["--random-cuts", "20", "--distance-samples", "100", "--trimesh-random", "3", "--trimesh-uniform", "8"]


# --------------------------------------------------------------------------
# byte-level helpers written here from docs/FORMAT.md (not from the checker)
# --------------------------------------------------------------------------

def header(data):
    G, C, P = struct.unpack_from("<III", data, 60)
    pt_off, pt_size = struct.unpack_from("<QQ", data, 96)
    return {"G": G, "C": C, "P": P, "pt_off": pt_off, "pt_end": pt_off + pt_size}


def group(data, g):
    off = 160 + 40 * g
    cx, cy, cz, radius, error, level, first, count, page = struct.unpack_from("<5f4I", data, off)
    return {"off": off, "center": (cx, cy, cz), "radius": radius, "error": error, "level": level,
            "first": first, "count": count, "page": page}


def cluster(data, c):
    h = header(data)
    off = 160 + 40 * h["G"] + 16 * c
    grp, own, vc, tc, poff = struct.unpack_from("<IIHHI", data, off)
    return {"group": grp, "own": own, "vc": vc, "tc": tc, "page_offset": poff}


def page(data, p):
    h = header(data)
    off = h["pt_off"] + 72 * p
    offset, csize, rsize = struct.unpack_from("<QII", data, off)
    first, count = struct.unpack_from("<II", data, off + 48)
    return {"rec": off, "offset": offset, "csize": csize, "rsize": rsize, "first": first, "count": count}


def fix_meta_checksum(data):
    h = header(data)
    hasher = blake3.blake3(bytes(data[0:112]))
    hasher.update(bytes(data[160:h["pt_end"]]))
    data[112:144] = hasher.digest()


# --------------------------------------------------------------------------
# fixtures
# --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    if not MRES.exists() or not BAKE_ALL.exists():
        pytest.skip("Rust tools not built: cargo build --release -p mres-cli")
    d = tmp_path_factory.mktemp("mres")
    meshes = d / "meshes"
    meshes.mkdir()
    for kind, n in (("sphere", "16"), ("terrain", "30"), ("boxes", "24")):
        subprocess.run([str(MRES), "generate", kind, n, "-o", str(meshes / f"{kind}.obj")],
                       check=True, capture_output=True)
    out = d / "out"
    subprocess.run([str(BAKE_ALL), str(meshes), "-o", str(out), "-j", "1"], check=True, capture_output=True)
    files = {k: out / f"{k}.mres" for k in ("sphere", "terrain", "boxes")}
    for f in files.values():
        assert f.exists(), f
    return d, files


def run_checker(*args):
    proc = subprocess.run([sys.executable, str(CHECKER), *map(str, args)], capture_output=True, text=True,
                          timeout=300)
    return proc


def corrupted(baked, name, tag, mutate):
    d, files = baked
    data = bytearray(files[name].read_bytes())
    mutate(data)
    path = d / f"{name}-{tag}.mres"
    path.write_bytes(bytes(data))
    return path


def assert_caught(proc, kind):
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out
    assert f"[{kind}]" in out, out
    assert "Traceback" not in out, out


# --------------------------------------------------------------------------
# valid files
# --------------------------------------------------------------------------

def test_valid_files_pass_and_agree_with_rust_validator(baked):
    _, files = baked
    proc = run_checker(*files.values(), "--json", *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    reports = [json.loads(line) for line in proc.stdout.splitlines() if line.strip()]
    assert len(reports) == len(files)
    for rep, path in zip(reports, files.values()):
        assert rep["ok"] and rep["violation_count"] == 0, rep
        assert rep["uniform_cuts"] >= 2 and rep["random_cuts"] == 20 and rep["trimesh_cuts"] >= 2
        rust = json.loads(subprocess.run([str(MRES), "validate", str(path), "--json", "--random-cuts", "10"],
                                         check=True, capture_output=True, text=True).stdout)
        assert rep["levels"] == rust["levels"]
        assert rep["root_groups"] == rust["root_groups"]
        assert rep["root_clusters"] == rust["root_clusters"]
        assert rep["pages"] == rust["pages"]
        assert rep["uniform_cuts"] == rust["uniform_cuts"]
        assert rep["level0_fill"] == pytest.approx(rust["level0_fill"])
        mine = [(x["level"], x["clusters"], x["groups"], x["triangles"]) for x in rep["per_level"]]
        theirs = [(x["level"], x["clusters"], x["groups"], x["triangles"]) for x in rust["per_level"]]
        assert mine == theirs


def test_text_output_and_source_distance(baked):
    d, files = baked
    proc = run_checker(files["sphere"], "--source", d / "meshes" / "sphere.obj", *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout and "source distance" in proc.stdout
    # the level-0 surface is the source quantized to the grid: within a grid step
    proc = run_checker(files["sphere"], "--source", d / "meshes" / "sphere.obj", "--json", *FAST)
    rep = json.loads(proc.stdout)
    assert rep["source_distance"]["level0_to_source"]["max_steps"] < 1.0
    assert rep["source_distance"]["source_to_level0"]["max_steps"] < 1.0


def test_missing_file_is_io_error(baked):
    d, _ = baked
    proc = run_checker(d / "does-not-exist.mres")
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr


# --------------------------------------------------------------------------
# corruptions
# --------------------------------------------------------------------------

def test_flipped_page_byte_fails_page_checksum(baked):
    def mutate(data):
        p = page(data, 0)
        data[p["offset"] + p["csize"] // 2] ^= 0x5A
    proc = run_checker(corrupted(baked, "sphere", "flip", mutate), *FAST)
    assert_caught(proc, "page_checksum")
    assert "page 0" in proc.stdout


def test_flipped_hierarchy_byte_fails_meta_checksum(baked):
    def mutate(data):
        data[160 + 20] ^= 0x01  # group 0's level
    proc = run_checker(corrupted(baked, "sphere", "meta", mutate), *FAST)
    assert_caught(proc, "meta_checksum")


def parent_child(data):
    """A cluster c with an own group whose parent group (c's group) is not a root."""
    h = header(data)
    for c in range(h["C"]):
        cl = cluster(data, c)
        if cl["own"] != 0xFFFFFFFF:
            par = group(data, cl["group"])
            if par["error"] != float("inf"):
                return c, cl["group"], cl["own"]
    raise AssertionError("no non-root parent group")


def test_lowered_group_error_fails_monotone(baked):
    def mutate(data):
        c, par, own = parent_child(data)
        child_error = group(data, own)["error"]
        struct.pack_into("<f", data, group(data, par)["off"] + 16, child_error * 0.5)
        fix_meta_checksum(data)
    proc = run_checker(corrupted(baked, "sphere", "monotone", mutate), *FAST)
    assert_caught(proc, "monotone_error")
    assert "meta_checksum" not in proc.stdout


def test_shrunk_sphere_fails_nested(baked):
    def mutate(data):
        c, par, own = parent_child(data)
        off = group(data, par)["off"] + 12
        struct.pack_into("<f", data, off, group(data, own)["radius"] * 0.5)
        fix_meta_checksum(data)
    proc = run_checker(corrupted(baked, "sphere", "nested", mutate), *FAST)
    assert_caught(proc, "nested_spheres")
    assert "meta_checksum" not in proc.stdout


@pytest.mark.parametrize("keep", [100, 600, "half", "minus1"])
def test_truncated_file_is_a_clean_error(baked, keep):
    def mutate(data):
        n = len(data) // 2 if keep == "half" else len(data) - 1 if keep == "minus1" else keep
        del data[n:]
    proc = run_checker(corrupted(baked, "terrain", f"trunc{keep}", mutate), *FAST)
    out = proc.stdout + proc.stderr
    assert proc.returncode in (1, 2), out
    assert "Traceback" not in out
    assert "truncated" in out or "outside the file" in out, out


def test_bad_magic(baked):
    def mutate(data):
        data[0:4] = b"MREZ"
    proc = run_checker(corrupted(baked, "terrain", "magic", mutate), *FAST)
    assert_caught(proc, "bad_magic")


def test_changed_index_fails_crack_check(baked):
    """Change one triangle of a level-0 cluster in the last page (level-0 pages
    are last, so no other page moves), re-encode the page as a single zstd
    frame and fix both checksums: only the cut checks can notice."""
    info = {}

    def mutate(data):
        h = header(data)
        p = h["P"] - 1
        rec = page(data, p)
        comp = bytes(data[rec["offset"]:rec["offset"] + rec["csize"]])
        assert rec["offset"] + rec["csize"] == len(data)
        dobj = zstandard.ZstdDecompressor()
        raw = bytearray(dobj.stream_reader(comp, read_across_frames=True).read(rec["rsize"] + 1))
        assert len(raw) == rec["rsize"]
        for i in range(rec["count"]):
            c = rec["first"] + i
            cl = cluster(data, c)
            if cl["own"] == 0xFFFFFFFF and cl["vc"] > 3:
                break
        else:
            raise AssertionError("no level-0 cluster in the last page")
        hdr = 48 * i
        idx_off = struct.unpack_from("<I", raw, hdr + 32)[0]
        vc = struct.unpack_from("<H", raw, hdr)[0]
        t0 = raw[idx_off:idx_off + 3]
        # move the first corner of triangle 0 to a vertex not in the triangle
        new = next(v for v in range(vc) if v not in t0)
        raw[idx_off] = new
        info["cluster"] = c
        new_comp = zstandard.ZstdCompressor(level=3).compress(bytes(raw))
        data[rec["offset"]:] = new_comp
        struct.pack_into("<I", data, rec["rec"] + 8, len(new_comp))
        data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(new_comp).digest()
        fix_meta_checksum(data)

    proc = run_checker(corrupted(baked, "sphere", "index", mutate), *FAST)
    assert_caught(proc, "cracked_cut")
    # level 0 is the reference, so the change shows up in the coarser cuts,
    # which name the level-0 cluster that uses the broken edge
    assert "uniform cut t=" in proc.stdout, proc.stdout
    assert f"cluster {info['cluster']}" in proc.stdout, proc.stdout
    assert "page_checksum" not in proc.stdout and "meta_checksum" not in proc.stdout


def test_out_of_range_index_is_reported(baked):
    def mutate(data):
        h = header(data)
        rec = page(data, h["P"] - 1)
        comp = bytes(data[rec["offset"]:rec["offset"] + rec["csize"]])
        raw = bytearray(zstandard.ZstdDecompressor().stream_reader(comp, read_across_frames=True).read())
        idx_off = struct.unpack_from("<I", raw, 32)[0]
        assert struct.unpack_from("<H", raw, 0)[0] <= 255
        raw[idx_off + 1] = 255
        new_comp = zstandard.ZstdCompressor().compress(bytes(raw))
        data[rec["offset"]:] = new_comp
        struct.pack_into("<I", data, rec["rec"] + 8, len(new_comp))
        data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(new_comp).digest()
        fix_meta_checksum(data)
    proc = run_checker(corrupted(baked, "terrain", "oob", mutate), *FAST)
    assert_caught(proc, "index_out_of_range")


def test_one_bad_file_among_good_ones_exits_1(baked):
    _, files = baked

    def mutate(data):
        data[4] = 2  # version
    bad = corrupted(baked, "boxes", "version", mutate)
    proc = run_checker(files["terrain"], bad, *FAST)
    assert_caught(proc, "bad_version")
    assert f"{files['terrain']}: PASS" in proc.stdout


# --------------------------------------------------------------------------
# unit tests of the cut rules (section 6), in-process
# --------------------------------------------------------------------------

def load_checker(path):
    import types
    sys.path.insert(0, str(ROOT / "scripts"))
    import check_mres
    opts = types.SimpleNamespace(seed=1, random_cuts=0, distance_samples=0, trimesh_uniform=2, trimesh_random=0,
                                 no_trimesh=True, strict_topology=False, debug=True, source=None)
    rep = check_mres.Report(str(path))
    ch = check_mres.Checker(str(path), memoryview(Path(path).read_bytes()), opts, rep)
    ch.run()
    assert rep.ok, rep.violations
    return ch, rep


def test_edge_rule_odd_counts_and_special_edges():
    import numpy as np
    sys.path.insert(0, str(ROOT / "scripts"))
    import check_mres
    ch = check_mres.Checker.__new__(check_mres.Checker)
    ch.L0 = np.array([2, 2, 2, 1, 3, 0, 0])
    ch.special = (ch.L0 > 0) & (ch.L0 != 2)
    cnt = np.array([0, 2, 4, 1, 3, 4, 0])
    assert not ch.bad_edges(cnt).any()          # 0/2/4 on interior edges, exact on open/non-manifold
    assert ch.pinched_edges(cnt).tolist() == [False, False, True, False, False, True, False]
    cnt = np.array([1, 3, 2, 2, 1, 0, 5])
    assert ch.bad_edges(cnt).tolist() == [True, True, False, True, True, False, True]


def test_overlapping_levels_are_caught(baked):
    import numpy as np
    _, files = baked
    ch, rep = load_checker(files["sphere"])
    level0 = ch.clevel == 0
    assert ch.check_overlap("test cut", level0)
    # add the outputs of the group of cluster 0's parent: both levels drawn at once
    g = ch.cgroup[np.flatnonzero(level0)[0]]
    sel = level0 | (ch.cown == g)
    assert not ch.check_overlap("test cut", sel)
    assert "cut_overlap" in rep.violations
    assert f"of group {g}" in rep.violations["cut_overlap"]["examples"][0]
