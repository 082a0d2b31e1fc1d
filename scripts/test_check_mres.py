"""Tests of scripts/check_mres.py, the independent .mres checker.

Small meshes are generated and baked with the Rust tools (`mres generate`,
`bake-all`); the checker must pass them, agree with `mres validate --json`, and
catch corruptions made here byte by byte or by re-laying a page out with the
small page codec below (holes, T-junctions, wrong open-edge marks, broken
page encodings, layout pages that are not the canonical layout). Skipped when
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
import lz4.block
import meshopt
import numpy as np
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
# a small page codec written here from docs/FORMAT.md §4.3 and §5 (not from
# the checker): decodes a page's clusters, lets a test change them, and
# encodes the page again (re-sealing both checksums)
# --------------------------------------------------------------------------

NONE = 0xFFFFFFFF
FLAG_NORMALS, FLAG_UVS, FLAG_MATERIALS = 1, 2, 4


def page_encoded(data, p):
    rec = page(data, p)
    comp = bytes(data[rec["offset"]:rec["offset"] + rec["csize"]])
    return zstandard.ZstdDecompressor().stream_reader(comp, read_across_frames=True).read()


def byte_planes(enc, at, count, n):
    return [sum(enc[at + p * count + i] << (8 * p) for p in range(n)) for i in range(count)]


def signed(z):
    return (z >> 1) ^ -(z & 1)


def prediction_order(tri, vc):
    """[(vertex, (a, b, d) | (a,) | ())] in decoding order (§4.3)."""
    seen, pairs, out = set(), {}, []
    for t in range(0, len(tri), 3):
        c = tri[t:t + 3]
        for k in range(3):
            if c[k] in seen:
                continue
            a, b = c[(k + 1) % 3], c[(k + 2) % 3]
            key = frozenset((a, b))
            if a in seen and b in seen and key in pairs:
                pred = (a, b, pairs[key])
            elif a in seen or b in seen:
                pred = (a,) if a in seen else (b,)
            else:
                pred = (out[-1][0],) if out else ()
            seen.add(c[k])
            out.append((c[k], pred))
        for k in range(3):
            pairs[frozenset((c[k], c[(k + 1) % 3]))] = c[(k + 2) % 3]
    for v in range(vc):
        if v not in seen:
            out.append((v, (out[-1][0],)))
    return out


def predicted(values, pred, anchor):
    if len(pred) == 3:
        return [values[pred[0]][k] + values[pred[1]][k] - values[pred[2]][k] for k in range(len(anchor))]
    return values[pred[0]] if pred else anchor


def page_sources(data, p):
    """Page p's sources (§4.3): its dependencies before it, in the array's order."""
    rec = page(data, p)
    first, count = struct.unpack_from("<II", data, rec["rec"] + 64)
    at = header(data)["pt_off"] + 72 * header(data)["P"] + 4 * first
    return [q for q in struct.unpack_from(f"<{count}I", data, at) if q < p]


def source_values(data, p, decoded):
    """The vertices of page p's sources in source numbering (§4.3), each
    {attribute: value} with grid coordinates modulo 2^32 as decoding keeps them."""
    out = []
    for q in page_sources(data, p):
        for c in decode_page(data, q, decoded):
            for v in range(len(c["q"])):
                out.append({name: ([x % (1 << 32) for x in c[name][v]] if name == "q" else c[name][v])
                            for name in ("q", "normals", "uvs") if c[name] is not None})
    return out


def decode_page(data, p, decoded=None):
    """The clusters of page p: grid coordinates q, octahedral normals, UVs,
    indices, marks and materials (lists; None for what the file lacks).
    `decoded` caches pages by index (a page's sources are decoded first)."""
    decoded = {} if decoded is None else decoded
    if p in decoded:
        return decoded[p]
    sources = source_values(data, p, decoded)
    flags = struct.unpack_from("<I", data, 12)[0]
    rec = page(data, p)
    cls = [cluster(data, rec["first"] + i) for i in range(rec["count"])]
    enc = page_encoded(data, p)
    n, V, T = len(cls), sum(c["vc"] for c in cls), sum(c["tc"] for c in cls)
    planes, target_planes, far_planes = enc[0], enc[1], enc[2]
    lengths = struct.unpack_from(f"<{n}H", enc, 4)
    at = 4 + 2 * n
    coded_at = at
    at += sum(lengths)
    marks = list(enc[at:at + T])
    at += T
    copies = list(enc[at:at + V])
    at += V
    C, G = copies.count(1), copies.count(2)
    S = V - C - G
    targets = iter(byte_planes(enc, at, C, target_planes))
    at += target_planes * C
    far = iter(byte_planes(enc, at, G, far_planes))
    at += far_planes * G
    attrs = {"q": (byte_planes(enc, at, 3 * S, planes), 3, 32)}
    at += 3 * planes * S
    for name, flag in (("normals", FLAG_NORMALS), ("uvs", FLAG_UVS)):
        if flags & flag:
            attrs[name] = (byte_planes(enc, at, 2 * S, 2), 2, 16)
            at += 4 * S
    materials = byte_planes(enc, at, T, 2) if flags & FLAG_MATERIALS else None
    anchors = {name: [0] * lanes for name, (_, lanes, _) in attrs.items()}
    out, to, j, k, next_target, next_far = [], 0, 0, 0, 0, 0
    decoded_vertices = []  # every vertex of the page in decoding order: {attribute: value}
    for i, (c, L) in enumerate(zip(cls, lengths)):
        tri = [int(x) for x in meshopt.decode_index_buffer(bytes(enc[coded_at:coded_at + L]), 3 * c["tc"], 4)]
        coded_at += L
        order = prediction_order(tri, c["vc"])
        d = {"index": rec["first"] + i, "indices": tri, "marks": marks[to:to + c["tc"]],
             "materials": materials[to:to + c["tc"]] if materials else None, "normals": None, "uvs": None}
        values = {name: [None] * c["vc"] for name in attrs}
        for v, pred in order:
            if copies[j] == 2:
                u = next_far + signed(next(far))
                next_far = u + 1
                for name in attrs:
                    values[name][v] = sources[u][name]
            elif copies[j]:
                t = next_target + signed(next(targets))
                next_target = t + 1
                for name in attrs:
                    values[name][v] = decoded_vertices[t][name]
            else:
                for name, (res, lanes, bits) in attrs.items():
                    r = res[lanes * k:lanes * (k + 1)]
                    p_ = predicted(values[name], pred, anchors[name])
                    values[name][v] = [(x + signed(z)) % (1 << bits) for x, z in zip(p_, r)]
                k += 1
            decoded_vertices.append({name: values[name][v] for name in attrs})
            j += 1
        for name, (_, _, bits) in attrs.items():
            anchors[name] = values[name][order[0][0]]
            vals = values[name]
            if bits == 32:
                vals = [[x - (1 << 32) if x >= 1 << 31 else x for x in v] for v in vals]
            d[name] = vals
        out.append(d)
        to += c["tc"]
    decoded[p] = out
    return out


def canonical(indices, marks):
    """The triangles as the index codec gives them back (corners maybe
    rotated), marks rotated along (§4.3: what the writer stores)."""
    coded = meshopt.encode_index_buffer(np.array(indices, dtype=np.uint32))
    back = [int(x) for x in meshopt.decode_index_buffer(coded, len(indices), 4)]
    moved = []
    for t, m in enumerate(marks):
        o, r = indices[3 * t:3 * t + 3], back[3 * t:3 * t + 3]
        s = next(s for s in range(3) if all(r[k] == o[(k + s) % 3] for k in range(3)))
        moved.append(sum(((m >> ((k + s) % 3)) & 1) << k for k in range(3)))
    return back, moved, coded


def gpu_size(c, flags):
    """Bytes of a cluster's blocks in the GPU layout (§5), padding included."""
    def bits(values, lanes):
        return sum((max(v[k] for v in values) - min(v[k] for v in values)).bit_length() for k in range(lanes))
    vc, tc = len(c["q"]), len(c["indices"]) // 3
    words = lambda b: (b + 31) // 32 * 4  # noqa: E731
    size = 48 + words(vc * bits(c["q"], 3)) + (3 * tc + 3) // 4 * 4
    size += words(3 * tc) if any(c["marks"]) else 0
    size += words(vc * bits(c["normals"], 2)) if flags & FLAG_NORMALS else 0
    size += 4 * vc if flags & FLAG_UVS else 0
    size += (2 * tc + 3) // 4 * 4 if flags & FLAG_MATERIALS else 0
    return size


def zigzag(r, bits):
    r = (r + (1 << (bits - 1))) % (1 << bits) - (1 << (bits - 1))
    return ((r << 1) ^ (r >> (bits - 1))) & ((1 << bits) - 1)


def encode_page(clusters, flags):
    """The page's streams (§4.3) and its GPU layout size (§5): a vertex equal
    in every attribute to one decoded before it in the page is a copy of the
    latest such one."""
    lengths, coded, marks, materials = b"", b"", [], []
    res = {"q": [], "normals": [], "uvs": []}
    anchors = {"q": [0, 0, 0], "normals": [0, 0], "uvs": [0, 0]}
    latest, copies, targets, next_target = {}, [], [], 0
    for c in clusters:
        c["indices"], c["marks"], code = canonical(c["indices"], c["marks"])
        lengths += struct.pack("<H", len(code))
        coded += code
        marks += c["marks"]
        materials += c["materials"] or []
        # an index past the vertices (a test's corruption) predicts from the last one, as the
        # checker reads it, so that the page decodes and the checker sees the bad index
        order = prediction_order([min(i, len(c["q"]) - 1) for i in c["indices"]], len(c["q"]))
        names = [(name, bits) for name, bits in (("q", 32), ("normals", 16), ("uvs", 16)) if c[name] is not None]
        for v, pred in order:
            key = tuple(tuple(c[name][v]) for name, _ in names)
            earlier = latest.get(key)
            latest[key] = len(copies)
            copies.append(0 if earlier is None else 1)
            if earlier is not None:
                targets.append(zigzag(earlier - next_target, 32))
                next_target = earlier + 1
                continue
            for name, bits in names:
                values = c[name]
                res[name] += [zigzag(x - p, bits) for x, p in zip(values[v], predicted(values, pred, anchors[name]))]
        for name, _ in names:
            anchors[name] = c[name][order[0][0]]
    planes = max(1, max(((z.bit_length() + 7) // 8 for z in res["q"]), default=1))
    target_planes = max(((z.bit_length() + 7) // 8 for z in targets), default=0)
    streams = [bytes([planes, target_planes, 0, 0]), lengths, coded, bytes(marks), bytes(copies)]
    streams += [bytes((z >> (8 * p)) & 0xFF for z in targets) for p in range(target_planes)]
    streams += [bytes((z >> (8 * p)) & 0xFF for z in res["q"]) for p in range(planes)]
    for name in ("normals", "uvs"):
        if res[name]:
            streams += [bytes((z >> (8 * p)) & 0xFF for z in res[name]) for p in range(2)]
    if flags & FLAG_MATERIALS:
        streams += [bytes((m >> (8 * p)) & 0xFF for m in materials) for p in range(2)]
    return streams, sum(gpu_size(c, flags) for c in clusters)


def store_page(data, p, comp, raw_size=None, counts=()):
    """Puts `comp` in place of page p's bytes: moves the later pages and fixes
    the page record (raw_size when given), cluster counts and checksums."""
    h = header(data)
    rec = page(data, p)
    data[rec["offset"]:rec["offset"] + rec["csize"]] = comp
    delta = len(comp) - rec["csize"]
    for q in range(p + 1, h["P"]):
        r = page(data, q)
        struct.pack_into("<Q", data, r["rec"], r["offset"] + delta)
    struct.pack_into("<I", data, rec["rec"] + 8, len(comp))
    if raw_size is not None:
        struct.pack_into("<I", data, rec["rec"] + 12, raw_size)
    data[rec["rec"] + 16:rec["rec"] + 48] = blake3.blake3(comp).digest()
    for index, vc, tc in counts:
        struct.pack_into("<HH", data, 160 + 40 * h["G"] + 16 * index + 8, vc, tc)
    fix_meta_checksum(data)


def replace_page(data, p, clusters, edit=None):
    """Stores page p encoded anew from `clusters` (`edit` may change the
    streams first), one zstd frame per stream as the writer does."""
    flags = struct.unpack_from("<I", data, 12)[0]
    streams, raw_size = encode_page(clusters, flags)
    if edit:
        edit(streams)
    comp = b"".join(zstandard.ZstdCompressor(level=3).compress(s) for s in streams if s)
    store_page(data, p, comp, raw_size, [(c["index"], len(c["q"]), len(c["indices"]) // 3) for c in clusters])


def all_clusters(data):
    decoded = {}
    return [c for p in range(header(data)["P"]) for c in decode_page(data, p, decoded)]


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
        assert struct.unpack_from("<I", f.read_bytes(), 4)[0] == 6, f"{f}: not format version 6 (stale build?)"
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
    are last, so no other page moves), re-encode the page and fix both
    checksums: only the cut checks can notice."""
    info = {}

    def mutate(data):
        p = header(data)["P"] - 1
        cls = decode_page(data, p)
        i = next(i for i, c in enumerate(cls) if cluster(data, c["index"])["own"] == NONE and len(c["q"]) > 3)
        c = cls[i]
        # move the first corner of triangle 0 to a vertex not in the triangle
        c["indices"][0] = next(v for v in range(len(c["q"])) if v not in c["indices"][:3])
        info["cluster"] = c["index"]
        replace_page(data, p, cls)

    proc = run_checker(corrupted(baked, "sphere", "index", mutate), *FAST)
    assert_caught(proc, "cracked_cut")
    # level 0 is the reference, so the change shows up in the coarser cuts,
    # which name the level-0 cluster that uses the broken edge
    assert "uniform cut t=" in proc.stdout, proc.stdout
    assert f"cluster {info['cluster']}" in proc.stdout, proc.stdout
    assert "page_checksum" not in proc.stdout and "meta_checksum" not in proc.stdout


def test_out_of_range_index_is_reported(baked):
    """An index naming a vertex the cluster does not have, in a valid index
    coding (§4.3: the reader checks the decoded indices)."""
    def mutate(data):
        p = header(data)["P"] - 1
        cls = decode_page(data, p)
        cls[0]["indices"][1] = len(cls[0]["q"])
        replace_page(data, p, cls)
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
    decoded = {}
    for p in range(header(data)["P"]):
        cls = decode_page(data, p, decoded)
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
        cls[i]["materials"] = cls[i]["materials"][:1] if cls[i]["materials"] else None
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
        for name in ("normals", "uvs"):
            if c[name]:
                c[name].append(c[name][a])
        if c["materials"]:
            c["materials"].append(c["materials"][t])
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
        if c["materials"]:
            c["materials"].append(c["materials"][t])
        replace_page(data, p, cls)
    proc = run_on(baked, "terrain", "marktwice", mutate)
    assert_caught(proc, "group_marked_twice")
    assert_caught(proc, "cracked_cut")
    assert re.search(r"\b[1-9][0-9]* marked more than once", proc.stdout), proc.stdout


# --------------------------------------------------------------------------
# the reader's checks of the page encoding (docs/FORMAT.md §4.3, §7)
# --------------------------------------------------------------------------

def edit_streams(baked, name, tag, edit):
    def mutate(data):
        replace_page(data, 0, decode_page(data, 0), edit)
    return run_on(baked, name, tag, mutate)


def test_reencoded_page_passes(baked):
    """The test codec writes what the writer writes: a page decoded and encoded
    again gives a file the checker passes."""
    def edit(streams):
        pass
    proc = edit_streams(baked, "terrain", "reencoded", edit)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_mark_over_seven_is_rejected(baked):
    def edit(streams):
        streams[3] = bytes([8]) + streams[3][1:]
    proc = edit_streams(baked, "sphere", "mark8", edit)
    assert_caught(proc, "page_encoding")
    assert "open-edge mark 8" in proc.stdout, proc.stdout


@pytest.mark.parametrize("which", ["planes0", "planes5", "targets5", "far5", "reserved"])
def test_bad_preamble_is_rejected(baked, which):
    def edit(streams):
        planes, targets = streams[0][0], streams[0][1]
        streams[0] = {"planes0": bytes([0, targets, 0, 0]), "planes5": bytes([5, targets, 0, 0]),
                      "targets5": bytes([planes, 5, 0, 0]), "far5": bytes([planes, targets, 5, 0]),
                      "reserved": bytes([planes, targets, 0, 1])}[which]
    proc = edit_streams(baked, "sphere", f"preamble-{which}", edit)
    assert_caught(proc, "page_encoding")
    assert "preamble" in proc.stdout, proc.stdout


def test_page_zero_has_copies(baked):
    """The copy tests below need copies in page 0 (cluster borders shared
    within the page)."""
    _, files = baked
    streams, _ = encode_page(decode_page(bytearray(files["sphere"].read_bytes()), 0), 1)
    assert streams[0][1] >= 1 and sum(streams[4]) > 0


@pytest.mark.parametrize("which", ["ahead", "before"])
def test_bad_copy_target_is_rejected(baked, which):
    """A copy names a vertex not decoded yet, or one before the page's first:
    the lengths still match, the target does not."""
    def edit(streams):
        first = streams[4].index(1)
        # the first copy's target is coded against 0: put it at the copy itself, or at -1
        z = zigzag(first, 32) if which == "ahead" else zigzag(-1, 32)
        planes = streams[0][1]
        assert z < 1 << (8 * planes), "the target needs more planes than the page has"
        for p in range(planes):
            streams[5 + p] = bytes([(z >> (8 * p)) & 0xFF]) + streams[5 + p][1:]
    proc = edit_streams(baked, "sphere", f"target-{which}", edit)
    assert_caught(proc, "page_encoding")
    assert "copies vertex" in proc.stdout, proc.stdout


def test_bad_reference_flag_is_rejected(baked):
    def edit(streams):
        streams[4] = bytes([3]) + streams[4][1:]
    proc = edit_streams(baked, "sphere", "flag3", edit)
    assert_caught(proc, "page_encoding")
    assert "reference flag 3" in proc.stdout, proc.stdout


def test_short_encoding_is_rejected(baked):
    def edit(streams):
        streams[-1] = streams[-1][:-1]
    proc = edit_streams(baked, "sphere", "short", edit)
    assert_caught(proc, "page_encoding")
    assert "encoded bytes" in proc.stdout, proc.stdout


def test_wrong_raw_size_is_rejected(baked):
    def mutate(data):
        rec = page(data, 0)
        struct.pack_into("<I", data, rec["rec"] + 12, rec["rsize"] + 4)
        fix_meta_checksum(data)
    proc = run_on(baked, "sphere", "rawsize", mutate)
    assert_caught(proc, "page_raw_size")


def test_index_codec_garbage_is_rejected(baked):
    def edit(streams):
        streams[2] = bytes([0x00]) + streams[2][1:]  # not the codec's version-1 header byte
    proc = edit_streams(baked, "sphere", "codec", edit)
    assert_caught(proc, "page_encoding")
    assert "index codec" in proc.stdout, proc.stdout


@pytest.mark.parametrize("version, why", [(1, "no open-edge marks"), (2, "re-bake"), (3, "re-bake"),
                                          (4, "re-bake"), (5, "no layout pages")])
def test_an_older_version_is_rejected_with_a_clear_message(baked, version, why):
    def mutate(data):
        data[4] = version
        fix_meta_checksum(data)
    proc = run_on(baked, "sphere", f"v{version}", mutate)
    assert_caught(proc, "bad_version")
    assert f"version {version}" in proc.stdout and why in proc.stdout, proc.stdout


def far_copies(data, p):
    """(encoded bytes, offset of the far target planes, far copies G, planes F)
    of page p (§4.3)."""
    rec = page(data, p)
    cls = [cluster(data, rec["first"] + i) for i in range(rec["count"])]
    enc = bytearray(page_encoded(data, p))
    n, V, T = len(cls), sum(c["vc"] for c in cls), sum(c["tc"] for c in cls)
    lengths = struct.unpack_from(f"<{n}H", enc, 4)
    refs_at = 4 + 2 * n + sum(lengths) + T
    refs = enc[refs_at:refs_at + V]
    return enc, refs_at + V + enc[1] * refs.count(1), refs.count(2), enc[2]


@pytest.fixture(scope="module")
def paged(tmp_path_factory):
    """A file of several pages (the small ones above fit in one): (directory,
    {"sphere": path})."""
    if not MRES.exists() or not BAKE_ALL.exists():
        pytest.skip("Rust tools not built: cargo build --release -p mres-cli")
    d = tmp_path_factory.mktemp("paged")
    subprocess.run([str(MRES), "generate", "sphere", "48", "-o", str(d / "sphere.obj")], check=True,
                   capture_output=True)
    subprocess.run([str(BAKE_ALL), str(d / "sphere.obj"), "-o", str(d / "out"), "-j", "1"], check=True,
                   capture_output=True)
    f = d / "out" / "sphere.mres"
    assert header(f.read_bytes())["P"] >= 3, f"{f}: fewer than 3 pages"
    return d, {"sphere": f}


def test_the_finest_page_copies_from_its_sources(paged):
    """Far copies are exercised: the finest page copies vertices from the
    coarser pages it depends on, and the file passes."""
    data = bytearray(paged[1]["sphere"].read_bytes())
    p = header(data)["P"] - 1
    _, _, G, F = far_copies(data, p)
    assert G > 0 and F >= 1 and page_sources(data, p), f"page {p} has no far copies"
    proc = run_checker(paged[1]["sphere"], *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_far_target_before_the_sources_is_rejected(paged):
    """The first far copy of the finest page names source vertex -1: the
    lengths still match, the target does not."""
    def mutate(data):
        p = header(data)["P"] - 1
        enc, at, G, F = far_copies(data, p)
        for k in range(F):
            enc[at + k * G] = 1 if k == 0 else 0  # zigzag(-1) = 1
        store_page(data, p, zstandard.ZstdCompressor(level=3).compress(bytes(enc)))
    proc = run_on(paged, "sphere", "far-before", mutate)
    assert_caught(proc, "page_encoding")
    assert "copies source vertex -1" in proc.stdout, proc.stdout


def test_a_page_whose_source_fails_is_reported(paged):
    """A source page that does not decode: the pages copying from it are
    reported too, not decoded from nothing."""
    def mutate(data):
        last = header(data)["P"] - 1
        q = page_sources(data, last)[0]
        rec = page(data, q)
        data[rec["offset"]] ^= 0xFF
    proc = run_checker(corrupted(paged, "sphere", "source-fails", mutate), *FAST)
    assert_caught(proc, "page_checksum")
    assert "did not decode" in proc.stdout, proc.stdout


# --------------------------------------------------------------------------
# layout pages (docs/FORMAT.md §4.4): the GPU layout (§5) in one LZ4 block
# --------------------------------------------------------------------------

FLAG_LAYOUT_PAGES = 8


def bit_stream(values, lanes, lo=None):
    """(per-lane minimum, fewest bits, bit stream §5.2) of values stored as
    offsets from their minimum (§5: position_min/bits, normal_min/bits), or
    from `lo` where a test gives one."""
    lo = lo or [min(v[k] for v in values) for k in range(lanes)]
    bits = [(max(v[k] for v in values) - lo[k]).bit_length() for k in range(lanes)]
    acc = at = 0
    for v in values:
        for k in range(lanes):
            acc |= (v[k] - lo[k]) << at
            at += bits[k]
    return lo, bits, acc.to_bytes((at + 31) // 32 * 4, "little")


def layout_page(clusters, flags):
    """A page's GPU layout (§5) from its clusters' values: 48-byte headers,
    then all positions blocks, normals, UVs, indices (each with its open-edge
    block, §5.7) and materials, each padded with zeros to 4 bytes."""
    pad = lambda b: b + bytes(-len(b) % 4)  # noqa: E731
    heads, blocks = [], []
    for c in clusters:
        pmin, pbits, pos = bit_stream(c["q"], 3, c.get("position_min"))
        nmin, nbits, nrm = bit_stream(c["normals"], 2) if flags & FLAG_NORMALS else ([0, 0], [0, 0], None)
        uvs = b"".join(struct.pack("<2H", *uv) for uv in c["uvs"]) if flags & FLAG_UVS else None
        idx = bytes(c["indices"])
        open_edges = int(any(c["marks"]))
        if open_edges:
            marks = sum(m << (3 * t) for t, m in enumerate(c["marks"]))  # 3 bits per triangle (§5.7)
            idx = pad(idx) + marks.to_bytes((3 * len(c["marks"]) + 31) // 32 * 4, "little")
        mat = struct.pack(f"<{len(c['materials'])}H", *c["materials"]) if flags & FLAG_MATERIALS else None
        heads.append((len(c["q"]), len(c["indices"]) // 3, pmin, pbits, open_edges, nmin, nbits))
        blocks.append([pos, nrm, uvs, idx, mat])
    at, offsets, body = 48 * len(clusters), [[0] * 5 for _ in clusters], []
    for kind in range(5):
        for i, b in enumerate(blocks):
            if b[kind] is not None:
                offsets[i][kind] = at
                body.append(pad(b[kind]))
                at += len(body[-1])
    out = b"".join(struct.pack("<2H3i4B5I2H2BH", vc, tc, *pmin, *pbits, ef, *offs, *nmin, *nbits, 0)
                   for (vc, tc, pmin, pbits, ef, nmin, nbits), offs in zip(heads, offsets))
    return out + b"".join(body)


def layout_raw(data, p):
    """Page p's GPU layout: its LZ4 block decompressed to raw_size bytes (§4.4)."""
    rec = page(data, p)
    return bytearray(lz4.block.decompress(bytes(data[rec["offset"]:rec["offset"] + rec["csize"]]),
                                          uncompressed_size=rec["rsize"]))


def store_layout(data, p, raw):
    """Puts page p's layout `raw` back as one LZ4 block (raw_size kept)."""
    store_page(data, p, lz4.block.compress(bytes(raw), store_size=False))


CLUSTER_HEADER = {"position_min": (4, "<3i"), "normal_min": (40, "<2H"), "positions_offset": (20, "<I"),
                  "indices_offset": (32, "<I")}  # §5.1: byte offset and type of a few fields


def cluster_field(raw, i, name):
    at, fmt = CLUSTER_HEADER[name]
    return list(struct.unpack_from(fmt, raw, 48 * i + at))


def set_cluster_field(raw, i, name, *values):
    at, fmt = CLUSTER_HEADER[name]
    struct.pack_into(fmt, raw, 48 * i + at, *values)


def assert_layout_caught(proc, kind, message):
    """Reported as `kind` with `message`, cleanly: no traceback, and no
    exception the checker had to turn into a violation."""
    assert_caught(proc, kind)
    assert message in proc.stdout and "[checker_error]" not in proc.stdout, proc.stdout


@pytest.fixture(scope="module")
def layout(baked):
    """The baked files repacked with layout pages (§4.4): (directory,
    {name: path}), like `baked`."""
    d, files = baked
    out = {}
    for name in ("sphere", "terrain"):
        out[name] = d / f"{name}-layout.mres"
        subprocess.run([str(MRES), "repack", str(files[name]), "--pages", "layout", "-o", str(out[name])],
                       check=True, capture_output=True)
        assert struct.unpack_from("<I", out[name].read_bytes(), 12)[0] & FLAG_LAYOUT_PAGES
    return d, out


def test_layout_pages_pass_and_agree_with_the_compact_file(baked, layout):
    """A file of layout pages passes, agrees with `mres validate`, and gives
    the figures of the compact file it was repacked from."""
    names = list(layout[1])
    proc = run_checker(*(layout[1][n] for n in names), *(baked[1][n] for n in names), "--json", *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    reports = [json.loads(line) for line in proc.stdout.splitlines() if line.strip()]
    ignore = {"file", "bytes", "flags", "page_encoding", "zstd_frames_per_page", "timings", "seconds"}
    for name, rep, compact in zip(names, reports, reports[len(names):]):
        assert rep["ok"] and rep["page_encoding"] == "layout" and "layout_pages" in rep["flags"], rep
        assert compact["page_encoding"] == "compact", compact
        assert {k: v for k, v in rep.items() if k not in ignore} == {k: v for k, v in compact.items() if k not in ignore}
        rust = json.loads(subprocess.run([str(MRES), "validate", str(layout[1][name]), "--json", "--random-cuts", "10"],
                                         check=True, capture_output=True, text=True).stdout)
        assert rust["violation_count"] == 0 and rep["uniform_cuts"] == rust["uniform_cuts"], rust
        per_level = lambda r: [(x["level"], x["clusters"], x["groups"], x["triangles"]) for x in r["per_level"]]  # noqa: E731
        assert (rep["levels"], rep["root_groups"], rep["root_clusters"], rep["pages"], per_level(rep)) == \
            (rust["levels"], rust["root_groups"], rust["root_clusters"], rust["pages"], per_level(rust))


def test_layout_writer_gives_the_repacked_layout(baked, layout):
    """The test's layout writer lays out the compact file's decoded values
    exactly as `mres repack` does (so the corruptions below change only what
    they mean to)."""
    for name in layout[1]:
        compact, data = bytearray(baked[1][name].read_bytes()), bytearray(layout[1][name].read_bytes())
        flags = struct.unpack_from("<I", compact, 12)[0]
        decoded = {}
        for p in range(header(data)["P"]):
            assert layout_page(decode_page(compact, p, decoded), flags) == layout_raw(data, p), (name, p)


def padding_byte(raw, data):
    """The indices block's first padding byte (§5: blocks padded to 4 bytes)
    of the first cluster of page 0 that has one."""
    i = next(i for i in range(page(data, 0)["count"]) if 3 * cluster(data, i)["tc"] % 4)
    raw[cluster_field(raw, i, "indices_offset")[0] + 3 * cluster(data, i)["tc"]] = 1


def out_of_range_index(raw, data):
    assert cluster(data, 0)["vc"] < 256
    raw[cluster_field(raw, 0, "indices_offset")[0]] = cluster(data, 0)["vc"]


def moved_block(raw, data):
    set_cluster_field(raw, 0, "positions_offset", cluster_field(raw, 0, "positions_offset")[0] + 4)


def normal_min_2000(raw, data):
    """normal_min 2000 > 2^10 - 1: exact minima of values out of range."""
    assert struct.unpack_from("<I", data, 48)[0] == 10 and struct.unpack_from("<I", data, 12)[0] & FLAG_NORMALS
    set_cluster_field(raw, 0, "normal_min", 2000, cluster_field(raw, 0, "normal_min")[1])


def position_overflow(raw, data):
    """position_min at the i32 maximum: the exact minimum, but larger
    coordinates overflow i32 (§5.3)."""
    _, y, z = cluster_field(raw, 0, "position_min")
    set_cluster_field(raw, 0, "position_min", (1 << 31) - 1, y, z)


LAYOUT_EDITS = {  # which: (edit of page 0's layout, what the checker says)
    "index": (out_of_range_index, "index {vc} >= vertex_count {vc}"),
    "padding": (padding_byte, "not the canonical layout"),
    "moved": (moved_block, "not the canonical layout"),
    "normal_min": (normal_min_2000, "over 2^normal_bits - 1 = 1023"),
    "overflow": (position_overflow, "overflows i32"),
}


@pytest.mark.parametrize("which", list(LAYOUT_EDITS))
def test_bad_layout_page_is_rejected(baked, layout, which):
    """A layout page with one field or byte changed (§4.4: not the canonical
    layout, or not a layout at all), re-compressed and re-sealed."""
    edit, message = LAYOUT_EDITS[which]

    def mutate(data):
        raw = layout_raw(data, 0)
        edit(raw, data)
        store_layout(data, 0, raw)
    proc = run_on(layout, "sphere", f"layout-{which}", mutate)
    vc = cluster(bytearray(layout[1]["sphere"].read_bytes()), 0)["vc"]
    assert_layout_caught(proc, "page_layout", message.format(vc=vc))


@pytest.mark.parametrize("which", ["truncated", "short", "long"])
def test_bad_lz4_block_is_rejected(layout, which):
    """A truncated LZ4 block, one that decompresses to raw_size - 4 bytes
    (§4.4: exactly raw_size), and one longer than LZ4_compressBound(raw_size)."""
    def mutate(data):
        rec = page(data, 0)
        comp = bytes(data[rec["offset"]:rec["offset"] + rec["csize"]])
        rs = rec["rsize"]
        store_page(data, 0, {"truncated": comp[:-2],
                             "short": lz4.block.compress(bytes(layout_raw(data, 0)[:-4]), store_size=False),
                             "long": comp + bytes(rs + rs // 255 + 17 - len(comp))}[which])
    proc = run_on(layout, "sphere", f"lz4-{which}", mutate)
    message = {"truncated": "LZ4 error", "short": "its LZ4 block decompresses to", "long": "at most"}[which]
    assert_layout_caught(proc, "page_decompress", message)


def rotated_triangle(c):
    """Cluster c with one triangle's corners rotated (marks along) so that
    the index codec does not give it back as stored; a triangle whose
    vertices earlier triangles use, so that first-use order is kept."""
    tri = c["indices"]
    for t in range(1, len(tri) // 3):
        if set(tri[3 * t:3 * t + 3]) <= set(tri[:3 * t]):
            turned = tri[:3 * t] + tri[3 * t + 1:3 * t + 3] + [tri[3 * t]] + tri[3 * t + 3:]
            if canonical(turned, [0] * (len(tri) // 3))[0] != turned:
                m = c["marks"][t]
                c["marks"][t] = sum(((m >> ((k + 1) % 3)) & 1) << k for k in range(3))
                c["indices"] = turned
                return
    raise AssertionError("no triangle whose rotation the codec undoes")


def relabelled(c):
    """Cluster c with vertices 0 and 1 swapping numbers: not first-use order."""
    for name in ("q", "normals", "uvs"):
        if c[name]:
            c[name][0], c[name][1] = c[name][1], c[name][0]
    c["indices"] = [{0: 1, 1: 0}.get(x, x) for x in c["indices"]]


def lowered_minimum(c):
    """Cluster c's positions stored from a position_min 1 below their
    minimum: a layout of the right values, but not the exact minimum (§5)."""
    c["position_min"] = [min(v[0] for v in c["q"]) - 1] + [min(v[k] for v in c["q"]) for k in (1, 2)]


@pytest.mark.parametrize("which, message", [("first_use", "not numbered in first-use order"),
                                            ("rotated", "not as the index codec gives them back"),
                                            ("minimum", "not the canonical layout")])
def test_non_canonical_layout_of_the_values_is_rejected(baked, layout, which, message):
    """Page 0 laid out by the writer above from cluster 0's values in an
    order §4.4 does not allow (every other byte canonical), or with a
    minimum that is not exact."""
    def mutate(data):
        compact = bytearray(baked[1]["sphere"].read_bytes())
        cls = decode_page(compact, 0)
        {"first_use": relabelled, "rotated": rotated_triangle, "minimum": lowered_minimum}[which](cls[0])
        store_layout(data, 0, layout_page(cls, struct.unpack_from("<I", compact, 12)[0]))
    proc = run_on(layout, "sphere", f"layout-{which}", mutate)
    assert_layout_caught(proc, "page_layout", message)


@pytest.mark.parametrize("which, kind", [("page_offset", "cluster_page_offset"), ("group_page", "group_page"),
                                         ("group_range", "page_group_order")])
def test_hierarchy_and_page_table_must_agree(paged, which, kind):
    """Section 4.1 and 5: a cluster header away from 48*i of its page, a group
    naming another page than the one holding it, and pages whose group ranges
    are out of order (two pages' swapped) are violations here and errors of
    the Rust reader (`mres validate` fails)."""
    def mutate(data):
        h = header(data)
        last = page(data, h["P"] - 1)
        if which == "page_offset":
            off = 160 + 40 * h["G"] + 16 * (last["first"] + 1) + 12
            struct.pack_into("<I", data, off, 0)
        elif which == "group_page":
            struct.pack_into("<I", data, group(data, h["G"] - 1)["off"] + 32, 0)
        else:
            a, b = h["pt_off"] + 72 * 1 + 56, h["pt_off"] + 72 * 2 + 56
            ra, rb = bytes(data[a:a + 8]), bytes(data[b:b + 8])
            data[a:a + 8], data[b:b + 8] = rb, ra
        fix_meta_checksum(data)
    path = corrupted(paged, "sphere", f"agree-{which}", mutate)
    proc = run_checker(path, *FAST)
    assert_caught(proc, kind)
    assert f"VIOLATION [{kind}]" in proc.stdout, proc.stdout
    rust = subprocess.run([str(MRES), "validate", str(path)], capture_output=True, text=True)
    assert rust.returncode != 0 and "corrupt" in (rust.stdout + rust.stderr).lower(), rust.stdout + rust.stderr
