"""Tests of scripts/check_mres.py, the independent .mres checker.

Small meshes are generated and baked with the Rust tools (`mres generate`,
`bake-all`); the checker must pass them, agree with `mres validate --json`, and
catch corruptions made here byte by byte or by re-laying a page out with the
small page codec below (holes, T-junctions, wrong open-edge marks). Skipped when
the Rust tools are not built (cargo build --release -p mres-cli).

Run: .venv/bin/pytest scripts/test_check_mres.py -q
"""
from __future__ import annotations

import json
import re
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
# a small page codec written here from docs/FORMAT.md §5 (not from the
# checker): decodes a page's clusters into their blocks, lets a test change
# them, and lays the page out again (re-sealing both checksums)
# --------------------------------------------------------------------------

NONE = 0xFFFFFFFF
FLAG_NORMALS, FLAG_UVS, FLAG_MATERIALS = 1, 2, 4
OPEN_EDGES = 1


def bits_get(stream, bit, width):
    """Value of `width` bits at `bit` of a bit stream held as one integer (§5.2)."""
    return (stream >> bit) & ((1 << width) - 1)


def bits_bytes(stream, total_bits):
    return stream.to_bytes((total_bits + 31) // 32 * 4, "little")


def page_raw(data, p):
    rec = page(data, p)
    comp = bytes(data[rec["offset"]:rec["offset"] + rec["csize"]])
    raw = zstandard.ZstdDecompressor().stream_reader(comp, read_across_frames=True).read(rec["rsize"] + 1)
    assert len(raw) == rec["rsize"]
    return raw


def decode_page(data, p):
    """The clusters of page p: header fields, decoded positions (grid
    coordinates), indices and marks, and the other blocks as bytes."""
    flags = struct.unpack_from("<I", data, 12)[0]
    raw = page_raw(data, p)
    rec = page(data, p)
    out = []
    for i in range(rec["count"]):
        h = 48 * i
        vc, tc = struct.unpack_from("<HH", raw, h)
        pmin = list(struct.unpack_from("<3i", raw, h + 4))
        pbits = list(raw[h + 16:h + 19])
        edge_flags = raw[h + 19]
        offs = struct.unpack_from("<5I", raw, h + 20)
        nbits = list(raw[h + 44:h + 46])
        stride = sum(pbits)
        pos = int.from_bytes(raw[offs[0]:offs[0] + (vc * stride + 31) // 32 * 4], "little")
        q = []
        for v in range(vc):
            rec_v = bits_get(pos, v * stride, stride)
            q.append([pmin[0] + bits_get(rec_v, 0, pbits[0]), pmin[1] + bits_get(rec_v, pbits[0], pbits[1]),
                      pmin[2] + bits_get(rec_v, pbits[0] + pbits[1], pbits[2])])
        nstride = sum(nbits)
        normals = (int.from_bytes(raw[offs[1]:offs[1] + (vc * nstride + 31) // 32 * 4], "little")
                   if flags & FLAG_NORMALS else 0)
        uvs = raw[offs[2]:offs[2] + 4 * vc] if flags & FLAG_UVS else b""
        indices = list(raw[offs[3]:offs[3] + 3 * tc])
        marks = [0] * tc
        if edge_flags & OPEN_EDGES:
            start = offs[3] + (3 * tc + 3) // 4 * 4
            stream = int.from_bytes(raw[start:start + (3 * tc + 31) // 32 * 4], "little")
            marks = [bits_get(stream, 3 * t, 3) for t in range(tc)]
        materials = raw[offs[4]:offs[4] + 2 * tc] if flags & FLAG_MATERIALS else b""
        out.append({"index": rec["first"] + i, "q": q, "pmin": pmin, "pbits": pbits, "header": raw[h:h + 48],
                    "nbits": nbits, "normals": normals, "uvs": uvs, "indices": indices, "marks": marks,
                    "materials": materials})
    return out


def encode_page(clusters):
    """Lays a page out as §5 describes the writer: headers, then each kind of
    block cluster by cluster, the open-edge block right after its indices."""
    blocks = []
    for c in clusters:
        vc, tc = len(c["q"]), len(c["indices"]) // 3
        stride = sum(c["pbits"])
        pos = 0
        for v, (x, y, z) in enumerate(c["q"]):
            d = [x - c["pmin"][0], y - c["pmin"][1], z - c["pmin"][2]]
            assert all(0 <= d[k] < (1 << c["pbits"][k]) for k in range(3)), "vertex outside the cluster's range"
            pos |= (d[0] | d[1] << c["pbits"][0] | d[2] << (c["pbits"][0] + c["pbits"][1])) << (v * stride)
        idx = bytes(c["indices"])
        if any(c["marks"]):
            stream = 0
            for t, m in enumerate(c["marks"]):
                stream |= m << (3 * t)
            idx += b"\0" * (-len(idx) % 4) + bits_bytes(stream, 3 * tc)
        normals = bits_bytes(c["normals"], vc * sum(c["nbits"])) if c["header"][24:28] != b"\0" * 4 else None
        blocks.append([bits_bytes(pos, vc * stride), normals, c["uvs"] or None, idx, c["materials"] or None])
    heads = [bytearray(c["header"]) for c in clusters]
    body = bytearray()
    at = 48 * len(clusters)
    for kind in range(5):
        for c, b, h in zip(clusters, blocks, heads):
            off = 0
            if b[kind] is not None:
                off = at
                body += b[kind] + b"\0" * (-len(b[kind]) % 4)
                at = 48 * len(clusters) + len(body)
            struct.pack_into("<I", h, 20 + 4 * kind, off)
    for c, h in zip(clusters, heads):
        struct.pack_into("<HH", h, 0, len(c["q"]), len(c["indices"]) // 3)
        h[19] = OPEN_EDGES if any(c["marks"]) else 0
    return b"".join(heads) + bytes(body)


def replace_page(data, p, clusters, version=None):
    """Stores page p laid out anew from `clusters`: recompresses it, moves the
    later pages, and fixes the page record, cluster records, and checksums."""
    h = header(data)
    rec = page(data, p)
    raw = encode_page(clusters)
    comp = zstandard.ZstdCompressor(level=3).compress(raw)
    raw_size = len(raw)
    data[rec["offset"]:rec["offset"] + rec["csize"]] = comp
    delta = len(comp) - rec["csize"]
    for q in range(p + 1, h["P"]):
        r = page(data, q)
        struct.pack_into("<Q", data, r["rec"], r["offset"] + delta)
    struct.pack_into("<II", data, rec["rec"] + 8, len(comp), raw_size)
    data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(comp).digest()
    for c in clusters:
        struct.pack_into("<HH", data, 160 + 40 * h["G"] + 16 * c["index"] + 8, len(c["q"]), len(c["indices"]) // 3)
    if version is not None:
        struct.pack_into("<I", data, 4, version)
    fix_meta_checksum(data)


def all_clusters(data):
    return [c for p in range(header(data)["P"]) for c in decode_page(data, p)]


def edge_uses(c):
    """(triangle, corner k, welded edge key) of each edge use of cluster c."""
    for t in range(len(c["indices"]) // 3):
        tri = c["indices"][3 * t:3 * t + 3]
        for k in range(3):
            a, b = tuple(c["q"][tri[k]]), tuple(c["q"][tri[(k + 1) % 3]])
            yield t, k, (min(a, b), max(a, b))


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
        assert struct.unpack_from("<I", f.read_bytes(), 4)[0] == 2, f"{f}: not format version 2 (stale build?)"
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
    # the terrain's rim is open: its level 0 and its cuts carry marks
    assert reports[1]["level0_marked_edges"] > 0 and reports[0]["level0_marked_edges"] == 0
    for rep, path in zip(reports, files.values()):
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
        data[4] = 3  # version
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


def test_cut_rule_unmarked_even_marked_at_most_once():
    import numpy as np
    sys.path.insert(0, str(ROOT / "scripts"))
    import check_mres
    U = np.array([0, 2, 4, 0, 2, 1, 3, 0, 2])
    M = np.array([0, 0, 0, 1, 1, 0, 0, 2, 2])
    # even unmarked uses with at most one mark pass; odd unmarked uses (hole,
    # T-junction) and a second mark fail
    assert check_mres.Checker.bad_edges(U, M).tolist() == [False] * 5 + [True] * 4
    # an unmarked edge used 4 or more times is a pinch, unless level 0 already uses it so
    ch = check_mres.Checker.__new__(check_mres.Checker)
    ch.special = np.array([False, False, True, False])
    assert ch.pinched_edges(np.array([4, 2, 4, 6])).tolist() == [True, False, False, True]


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


# --------------------------------------------------------------------------
# holes, T-junctions and wrong marks (docs/FORMAT.md §6, rules (a), (b), (c))
# --------------------------------------------------------------------------

def pick(data, want_level0, test):
    """(page, clusters of that page, position in it) of the first cluster of
    the wanted kind for which test(cluster) holds. Outputs are taken only where
    some uniform cut draws them (own error < parent error)."""
    for p in range(header(data)["P"]):
        cls = decode_page(data, p)
        for i, c in enumerate(cls):
            rec = cluster(data, c["index"])
            level0 = rec["own"] == NONE
            if level0 != want_level0:
                continue
            if not level0 and group(data, rec["own"])["error"] >= group(data, rec["group"])["error"]:
                continue
            if test(c):
                return p, cls, i
    raise AssertionError("no such cluster")


def sibling_counts(data):
    """Uses of each edge by the clusters of one own group: {(own_group, edge key): uses}
    (own_group NONE: level 0)."""
    counts = {}
    for c in all_clusters(data):
        own = cluster(data, c["index"])["own"]
        for _, _, key in edge_uses(c):
            counts[own, key] = counts.get((own, key), 0) + 1
    return counts


def interior_use(data, c, counts):
    """An unmarked edge use of c whose edge c and its siblings (the clusters of
    its own group, or level 0) use exactly twice: an inner edge."""
    own = cluster(data, c["index"])["own"]
    for t, k, key in edge_uses(c):
        if not c["marks"][t] >> k & 1 and counts.get((own, key)) == 2:
            return t, k
    return None


def marked_use(c):
    return next(((t, k) for t, k, _ in edge_uses(c) if c["marks"][t] >> k & 1), None)


def run_on(baked, name, tag, mutate):
    proc = run_checker(corrupted(baked, name, tag, mutate), *FAST)
    assert "page_checksum" not in proc.stdout and "meta_checksum" not in proc.stdout, proc.stdout
    return proc


def test_hole_fails_level0_and_cut_rules(baked):
    """A level-0 cluster loses all its triangles but one: a hole."""
    info = {}

    def mutate(data):
        p, cls, i = pick(data, True, lambda c: len(c["indices"]) > 3)
        cls[i]["indices"] = cls[i]["indices"][:3]
        cls[i]["marks"] = cls[i]["marks"][:1]
        cls[i]["materials"] = cls[i]["materials"][:2]
        info["cluster"] = cls[i]["index"]
        replace_page(data, p, cls)
    proc = run_on(baked, "sphere", "hole", mutate)
    assert_caught(proc, "cracked_cut")
    assert_caught(proc, "level0_marks")
    assert "rule (c)" in proc.stdout and "a hole or T-junction" in proc.stdout, proc.stdout
    assert "rule (a)" in proc.stdout and f"cluster {info['cluster']}" in proc.stdout, proc.stdout


def test_dropped_cluster_breaks_the_cut(baked):
    """The cut at the second uniform threshold without one of its clusters."""
    import numpy as np
    _, files = baked
    ch, rep = load_checker(files["sphere"])
    sel = ch.uniform_sel(ch.T[1])
    assert ch.check_cut("full cut", sel) and not rep.violations
    dropped = int(np.flatnonzero(sel)[0])
    sel[dropped] = False
    assert not ch.check_cut("cut without one cluster", sel)
    msg = rep.violations["cracked_cut"]["examples"][0]
    assert "cut without one cluster" in msg and "a hole or T-junction" in msg, msg
    # the hole's rim is used once, by the dropped cluster's neighbours
    assert f"cluster {dropped} " not in msg.split("cut clusters using it:")[1].split(";")[0], msg


@pytest.mark.parametrize("level0", [True, False], ids=["level0", "output"])
def test_t_junction_is_caught(baked, level0):
    """A triangle (a, b, c) is split at the midpoint m of its edge ab into
    (a, m, c) and (m, b, c); the neighbour across ab still uses ab."""
    def mutate(data):
        counts = sibling_counts(data)
        room = lambda c: len(c["q"]) < 256 and len(c["indices"]) < 3 * 128  # noqa: E731
        p, cls, i = pick(data, level0, lambda c: room(c) and interior_use(data, c, counts) is not None)
        c = cls[i]
        t, k = interior_use(data, c, counts)
        tri = c["indices"][3 * t:3 * t + 3]
        a, b, o = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
        m = len(c["q"])
        c["q"].append([(x + y) // 2 for x, y in zip(c["q"][a], c["q"][b])])
        assert c["q"][m] not in (c["q"][a], c["q"][b])
        stride = sum(c["nbits"])
        c["normals"] |= bits_get(c["normals"], a * stride, stride) << (m * stride)
        c["uvs"] = c["uvs"] + c["uvs"][4 * a:4 * a + 4] if c["uvs"] else c["uvs"]
        c["materials"] = c["materials"] + c["materials"][2 * t:2 * t + 2] if c["materials"] else c["materials"]
        mark = c["marks"][t]
        bc, ca = mark >> ((k + 1) % 3) & 1, mark >> ((k + 2) % 3) & 1
        c["indices"][3 * t:3 * t + 3] = [a, m, o]   # edges am, mo, oa
        c["marks"][t] = ca << 2
        c["indices"] += [m, b, o]                   # edges mb, bo, om
        c["marks"].append(bc << 1)
        replace_page(data, p, cls)
    proc = run_on(baked, "terrain", f"tjunction-{level0}", mutate)
    assert_caught(proc, "cracked_cut")
    assert "a hole or T-junction" in proc.stdout, proc.stdout
    assert_caught(proc, "level0_marks" if level0 else "group_border_new")


@pytest.mark.parametrize("level0", [True, False], ids=["level0", "output"])
def test_wrongly_set_mark_is_caught(baked, level0):
    def mutate(data):
        counts = sibling_counts(data)
        p, cls, i = pick(data, level0, lambda c: interior_use(data, c, counts) is not None)
        t, k = interior_use(data, cls[i], counts)
        cls[i]["marks"][t] |= 1 << k
        replace_page(data, p, cls)
    proc = run_on(baked, "sphere", f"setmark-{level0}", mutate)
    if level0:
        assert_caught(proc, "level0_marks")
        assert "rule (a)" in proc.stdout and "1 of them marked (must be 0)" in proc.stdout, proc.stdout
    else:
        # the outputs now use an inner edge once unmarked: the group border moved
        assert_caught(proc, "group_border_new")
        assert "rule (b)" in proc.stdout, proc.stdout
    assert_caught(proc, "cracked_cut")


@pytest.mark.parametrize("level0", [True, False], ids=["level0", "output"])
def test_wrongly_cleared_mark_is_caught(baked, level0):
    def mutate(data):
        p, cls, i = pick(data, level0, lambda c: marked_use(c) is not None)
        t, k = marked_use(cls[i])
        cls[i]["marks"][t] &= ~(1 << k)
        replace_page(data, p, cls)
    proc = run_on(baked, "terrain", f"clearmark-{level0}", mutate)
    assert_caught(proc, "level0_marks" if level0 else "group_border_new")
    assert_caught(proc, "cracked_cut")
    assert "a hole or T-junction" in proc.stdout, proc.stdout


def test_marks_on_an_open_edge_twice_are_caught(baked):
    """Two outputs of one group both marking a rim edge (one of them through a
    duplicated triangle) break M_Out <= 1 and the cuts' M <= 1."""
    def mutate(data):
        p, cls, i = pick(data, False, lambda c: marked_use(c) is not None and len(c["indices"]) < 3 * 128)
        c = cls[i]
        t, _ = marked_use(c)
        c["indices"] += c["indices"][3 * t:3 * t + 3]
        c["marks"].append(c["marks"][t])
        c["materials"] = c["materials"] + c["materials"][2 * t:2 * t + 2] if c["materials"] else c["materials"]
        replace_page(data, p, cls)
    proc = run_on(baked, "terrain", "marktwice", mutate)
    assert_caught(proc, "group_marked_twice")
    assert_caught(proc, "cracked_cut")
    assert re.search(r"\b[1-9][0-9]* marked more than once", proc.stdout), proc.stdout


# --------------------------------------------------------------------------
# the reader's checks of the open-edge block (docs/FORMAT.md §5.7, §7)
# --------------------------------------------------------------------------

def edit_header_byte(baked, name, tag, cluster_in_page, value):
    def mutate(data):
        raw = bytearray(page_raw(data, 0))
        raw[48 * cluster_in_page + 19] = value
        comp = zstandard.ZstdCompressor().compress(bytes(raw))
        rec = page(data, 0)
        assert header(data)["P"] == 1
        data[rec["offset"]:] = comp
        struct.pack_into("<I", data, rec["rec"] + 8, len(comp))
        data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(comp).digest()
        fix_meta_checksum(data)
    return run_on(baked, name, tag, mutate)


def test_unknown_edge_flags_bit(baked):
    proc = edit_header_byte(baked, "sphere", "edgeflags", 0, 0x02)
    assert_caught(proc, "cluster_edge_flags")
    assert "cluster 0" in proc.stdout


def test_open_edge_flag_without_a_block_overlaps_the_next_block(baked):
    """On a closed mesh no cluster has a block: the flag on cluster 0 makes its
    block land on the next cluster's indices."""
    proc = edit_header_byte(baked, "sphere", "noblock", 0, 0x01)
    assert_caught(proc, "open_edge_block_overlap")
    assert "open-edge block of cluster 0" in proc.stdout, proc.stdout


def test_nonzero_unused_mark_bits(baked):
    def mutate(data):
        p, cls, i = pick(data, True, lambda c: marked_use(c) is not None and (3 * len(c["indices"]) // 3) % 32)
        raw = bytearray(encode_page(cls))
        h = 48 * i
        tc = len(cls[i]["indices"]) // 3
        start = struct.unpack_from("<I", raw, h + 32)[0] + (3 * tc + 3) // 4 * 4
        last = start + (3 * tc + 31) // 32 * 4 - 1
        raw[last] |= 0x80                          # the last word's top bit is unused
        comp = zstandard.ZstdCompressor().compress(bytes(raw))
        rec = page(data, p)
        replace_page(data, p, cls)                 # same layout and sizes, then the flipped bit
        rec = page(data, p)
        data[rec["offset"]:rec["offset"] + rec["csize"]] = comp
        struct.pack_into("<I", data, rec["rec"] + 8, len(comp))
        data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(comp).digest()
        fix_meta_checksum(data)
    proc = run_on(baked, "terrain", "unusedbits", mutate)
    assert_caught(proc, "open_edge_unused_bits")


def test_version_1_is_rejected_with_a_clear_message(baked):
    def mutate(data):
        data[4] = 1
        fix_meta_checksum(data)
    proc = run_on(baked, "sphere", "v1", mutate)
    assert_caught(proc, "bad_version")
    assert "version 1" in proc.stdout and "no open-edge marks" in proc.stdout, proc.stdout
