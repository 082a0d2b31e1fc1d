#!/usr/bin/env python3
"""Independent checker for `.mres` files (format version 6).

Written from docs/FORMAT.md alone, as a second implementation next to the Rust
reader/validator: it reads every section with numpy, verifies checksums,
references and ranges (spec section 7), decodes every page to its GPU layout
(a compact page from its encoding, section 4.3; a layout page from its LZ4
block, which must hold the canonical layout, section 4.4) and every cluster
from that (section 5, with its open-edge marks), checks the DAG invariants the
selection rule relies on (section 6), checks the marks of level 0 and of every
group, checks that uniform and view-dependent cuts are crack-free by counting
welded edges (unmarked uses even, marked uses at most one), cross-checks cut
topology with trimesh (a cut's boundary edges are its marked edges) and
measures cut-to-level-0 distances.

Usage:
    check_mres.py FILE.mres [FILE.mres ...] [--source MESH] [--random-cuts N]
                  [--seed S] [--json] [--distance-samples N]

Exit status: 0 every file passes, 1 some file has a violation, 2 usage or I/O
error (a file that cannot be opened or read).
"""
from __future__ import annotations

import argparse
import io
import json
import math
import struct
import sys
import time

try:
    import numpy as np
    import blake3
    import zstandard
    import meshopt
    import lz4.block
except ImportError as exc:  # pragma: no cover - environment problem
    print(f"check_mres: missing dependency ({exc}); "
          "pip install -r scripts/requirements.txt", file=sys.stderr)
    sys.exit(2)

# ---------------------------------------------------------------------------
# Format constants (docs/FORMAT.md)
# ---------------------------------------------------------------------------

MAGIC = b"MRES"
VERSION = 6
HEADER_SIZE = 160
GROUP_SIZE = 40
CLUSTER_SIZE = 16
PAGE_SIZE = 72
CLUSTER_HEADER_SIZE = 48
MAX_RAW_SIZE = 16 * 1024 * 1024
MAX_ENCODED_SIZE = 32 * 1024 * 1024
NONE = 0xFFFFFFFF

FLAG_NORMALS = 1
FLAG_UVS = 2
FLAG_MATERIALS = 4
FLAG_LAYOUT_PAGES = 8  # every page is its GPU layout in one LZ4 block (section 4.4)
KNOWN_FLAGS = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS | FLAG_LAYOUT_PAGES
EDGE_OPEN = 1  # cluster header edge_flags bit 0: the cluster has an open-edge block

# header bytes 0..112 (the checksum follows at 112, reserved at 144..160)
HEADER_FMT = "<4sIII3ff2f2fIIIIIIQQQQQ"
assert struct.calcsize(HEADER_FMT) == 112

GROUP_DT = np.dtype([
    ("center", "<f4", (3,)), ("radius", "<f4"), ("error", "<f4"),
    ("level", "<u4"), ("first_cluster", "<u4"), ("cluster_count", "<u4"),
    ("page", "<u4"), ("reserved", "<u4"),
])
CLUSTER_DT = np.dtype([
    ("group", "<u4"), ("own_group", "<u4"), ("vertex_count", "<u2"),
    ("triangle_count", "<u2"), ("page_offset", "<u4"),
])
PAGE_DT = np.dtype([
    ("offset", "<u8"), ("compressed_size", "<u4"), ("raw_size", "<u4"),
    ("checksum", "u1", (32,)), ("first_cluster", "<u4"), ("cluster_count", "<u4"),
    ("first_group", "<u4"), ("group_count", "<u4"),
    ("dependency_first", "<u4"), ("dependency_count", "<u4"),
])
CHDR_DT = np.dtype([
    ("vertex_count", "<u2"), ("triangle_count", "<u2"),
    ("position_min", "<i4", (3,)), ("position_bits", "u1", (3,)), ("edge_flags", "u1"),
    ("positions_offset", "<u4"), ("normals_offset", "<u4"), ("uvs_offset", "<u4"),
    ("indices_offset", "<u4"), ("materials_offset", "<u4"),
    ("normal_min", "<u2", (2,)), ("normal_bits", "u1", (2,)), ("reserved1", "<u2"),
])
assert GROUP_DT.itemsize == GROUP_SIZE and CLUSTER_DT.itemsize == CLUSTER_SIZE
assert PAGE_DT.itemsize == PAGE_SIZE and CHDR_DT.itemsize == CLUSTER_HEADER_SIZE

# random view-dependent cuts (spec section 6 formula, parameters from the brief)
TAUS = (0.25, 0.5, 1.0, 2.0, 4.0, 16.0)
VIEW_H = 1080.0
FOV_Y_DEG = 60.0

MAX_EXAMPLES = 5

# what the versions this checker rejects lacked (docs/FORMAT.md section 8)
OLD_VERSIONS = {
    1: "has no open-edge marks",
    2: "stored pages in the GPU layout itself",
    3: "stored every vertex of a page with residuals, without copies of repeated vertices",
    4: "stored every vertex again that an earlier dependency page holds, without far copies",
    5: "has no layout pages (header flag LAYOUT_PAGES)",
}


class Fatal(Exception):
    """A violation after which the rest of the file cannot be interpreted."""


class Report:
    """Violations (the file breaks the spec) and notes (information)."""

    def __init__(self, path):
        self.path = path
        self.violations = {}
        self.warnings = {}
        self.notes = {}
        self.figures = {}
        self.io_error = None

    @staticmethod
    def _add(table, kind, count, examples):
        entry = table.setdefault(kind, {"count": 0, "examples": []})
        entry["count"] += int(count)
        room = MAX_EXAMPLES - len(entry["examples"])
        if room > 0:
            entry["examples"].extend(examples[:room])

    def violation(self, kind, msg, count=1):
        self._add(self.violations, kind, count, [msg])

    def warn(self, kind, msg, count=1):
        """Suspicious but not forbidden by the spec (e.g. topology changes)."""
        self._add(self.warnings, kind, count, [msg])

    def note(self, kind, msg, count=1):
        self._add(self.notes, kind, count, [msg])

    def violations_where(self, kind, mask_or_idx, fmt):
        """Record one violation per index in mask_or_idx, formatting a few."""
        idx = np.asarray(mask_or_idx)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        if idx.size:
            self._add(self.violations, kind, idx.size,
                      [fmt(int(i)) for i in idx[:MAX_EXAMPLES]])
        return idx.size

    def notes_where(self, kind, mask_or_idx, fmt):
        idx = np.asarray(mask_or_idx)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        if idx.size:
            self._add(self.notes, kind, idx.size,
                      [fmt(int(i)) for i in idx[:MAX_EXAMPLES]])
        return idx.size

    def fatal(self, kind, msg):
        self.violation(kind, msg)
        raise Fatal(msg)

    @property
    def violation_count(self):
        return sum(v["count"] for v in self.violations.values())

    @property
    def ok(self):
        return self.io_error is None and not self.violations


# ---------------------------------------------------------------------------
# numpy helpers
# ---------------------------------------------------------------------------

def seg_arange(counts):
    """Concatenation of arange(n) for each n in counts."""
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.cumsum(counts) - counts
    return np.arange(total, dtype=np.int64) - np.repeat(starts, counts)


def read_bits(words, word0, bitpos, width):
    """Value of `width` bits at bit `bitpos` of the stream starting at word
    index `word0` (spec section 5.2: LSB first, may straddle two words)."""
    w = word0 + (bitpos >> 5)
    shift = (bitpos & 31).astype(np.uint64)
    lo = words[w].astype(np.uint64)
    hi = words[w + 1].astype(np.uint64) << np.uint64(32)
    mask = (np.uint64(1) << width.astype(np.uint64)) - np.uint64(1)
    return (((lo | hi) >> shift) & mask).astype(np.int64)


def decompress_frames(comp, limit):
    """Decompress one or more concatenated zstd frames, producing at most
    limit + 1 bytes (so an oversized page is detected without inflating it)."""
    dctx = zstandard.ZstdDecompressor()
    reader = dctx.stream_reader(io.BytesIO(comp), read_across_frames=True)
    chunks = []
    got = 0
    limit = limit + 1
    while got < limit:
        chunk = reader.read(min(limit - got, 1 << 20))
        if not chunk:
            break
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


# ---------------------------------------------------------------------------
# page encoding (spec section 4.3) and the GPU layout it decodes to (section 5)
# ---------------------------------------------------------------------------

class PageError(Exception):
    """Encoded page bytes that do not decode (spec section 4.3)."""


def max_encoded_len(flags, vcs, tcs):
    """E_max of section 4.3 for a page of clusters with these counts."""
    n, V, T = len(vcs), int(sum(vcs)), int(sum(tcs))
    return (4 + 2 * n + 17 * n + 8 * T + T + V + 12 * V + (4 * V if flags & FLAG_NORMALS else 0)
            + (4 * V if flags & FLAG_UVS else 0) + (2 * T if flags & FLAG_MATERIALS else 0))


def planes(enc, at, count, nplanes):
    """count values stored as nplanes byte planes at enc[at:] (section 4.3)."""
    out = np.zeros(count, dtype=np.int64)
    for p in range(nplanes):
        out |= np.frombuffer(enc, np.uint8, count, at + p * count).astype(np.int64) << (8 * p)
    return out.tolist()


def unzigzag(z, bits):
    r = (z >> 1) ^ -(z & 1)
    return r


def decoding_order(tri, vc):
    """(vertex, prediction) in decoding order (section 4.3): a prediction is
    ("par", a, b, d), ("vtx", a) or ("anchor",)."""
    seen = [False] * vc
    edges = {}
    out = []
    for t in range(len(tri) // 3):
        c = tri[3 * t:3 * t + 3]
        for k in range(3):
            v = c[k]
            if seen[v]:
                continue
            a, b = c[(k + 1) % 3], c[(k + 2) % 3]
            if seen[a] and seen[b] and (min(a, b), max(a, b)) in edges:
                pred = ("par", a, b, edges[(min(a, b), max(a, b))])
            elif seen[a]:
                pred = ("vtx", a)
            elif seen[b]:
                pred = ("vtx", b)
            else:
                pred = ("vtx", out[-1][0]) if out else ("anchor",)
            seen[v] = True
            out.append((v, pred))
        for k in range(3):
            x, y = c[k], c[(k + 1) % 3]
            edges[(min(x, y), max(x, y))] = c[(k + 2) % 3]
    for v in range(vc):
        if not seen[v]:
            out.append((v, ("vtx", out[-1][0]) if out else ("anchor",)))
    return out


def wrap32(x):
    return ((x + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)


def wrap16(x):
    return x & 0xFFFF


def decode_encoded_page(enc, vcs, tcs, flags, sources=()):
    """The clusters of a page from its encoded bytes (section 4.3): per cluster
    a dict of grid coordinates q, octahedral values, UVs, indices, marks and
    materials. `sources` lists the vertices of the page's sources in source
    numbering, each a tuple (q, octahedral value, UV) (None for what the file
    lacks). Raises PageError."""
    n, V, T = len(vcs), int(sum(vcs)), int(sum(tcs))
    if len(enc) < 4 + 2 * n:
        raise PageError(f"{len(enc)} encoded bytes, shorter than the preamble and index lengths")
    P, R, F = enc[0], enc[1], enc[2]
    if not 1 <= P <= 4 or R > 4 or F > 4 or enc[3]:
        raise PageError(f"preamble {enc[0:4].hex()}: position planes outside 1..=4, target or far target "
                        "planes over 4 or reserved byte not zero")
    lengths = struct.unpack_from(f"<{n}H", enc, 4)
    for i, (L, t) in enumerate(zip(lengths, tcs)):
        if L > 17 + 8 * t:
            raise PageError(f"cluster {i} of the page: {L} bytes of coded indices for {t} triangles "
                            f"(at most {17 + 8 * t})")
    has_n, has_u, has_m = bool(flags & FLAG_NORMALS), bool(flags & FLAG_UVS), bool(flags & FLAG_MATERIALS)
    at = 4 + 2 * n
    coded_at = at
    at += sum(lengths)
    marks = list(enc[at:at + T])
    at += T
    refs = list(enc[at:at + V])
    if len(refs) < V:
        raise PageError(f"{len(enc)} encoded bytes end before the reference flags")
    at += V
    bad = [f for f in refs if f > 2]
    if bad:
        raise PageError(f"reference flag {bad[0]} is none of 0, 1 and 2")
    Cp, G = refs.count(1), refs.count(2)
    S = V - Cp - G
    expect = (4 + 2 * n + sum(lengths) + T + V + R * Cp + F * G + 3 * P * S + 4 * S * has_n + 4 * S * has_u
              + 2 * T * has_m)
    if len(enc) != expect:
        raise PageError(f"{len(enc)} encoded bytes, the counts, index lengths, {P} planes, {Cp} copies with "
                        f"{R} target planes and {G} far copies with {F} planes need {expect}")
    bad = [m for m in marks if m > 7]
    if bad:
        raise PageError(f"open-edge mark {bad[0]} has bits above bit 2")
    targets = [unzigzag(z, 32) for z in planes(enc, at, Cp, R)]
    at += R * Cp
    far = [unzigzag(z, 32) for z in planes(enc, at, G, F)]
    at += F * G
    pos = [unzigzag(z, 32) for z in planes(enc, at, 3 * S, P)]
    at += 3 * P * S
    nrm = uvs = mat = None
    if has_n:
        nrm = [unzigzag(z, 16) for z in planes(enc, at, 2 * S, 2)]
        at += 4 * S
    if has_u:
        uvs = [unzigzag(z, 16) for z in planes(enc, at, 2 * S, 2)]
        at += 4 * S
    if has_m:
        mat = planes(enc, at, T, 2)
    out = []
    to = 0
    page = {"refs": refs, "targets": iter(targets), "next_target": 0, "decoded": [], "stored": 0,
            "far": iter(far), "next_far": 0, "sources": sources,
            "anchor": ([0, 0, 0], [0, 0], [0, 0])}
    for i, (L, vc, tc) in enumerate(zip(lengths, vcs, tcs)):
        vc, tc = int(vc), int(tc)
        coded = bytes(enc[coded_at:coded_at + L])
        coded_at += L
        try:
            tri = meshopt.decode_index_buffer(coded, 3 * tc, 4).astype(np.int64).tolist()
        except Exception as exc:  # the codec's own error, whatever its type
            raise PageError(f"cluster {i} of the page: the index codec rejects its {L} bytes ({exc})")
        # indices >= vertex_count are reported on the GPU layout; here they
        # would name vertices that do not exist: clamp for the prediction only
        safe = [min(x, vc - 1) if x >= vc else x for x in tri]
        if any(x >= 256 for x in tri):
            raise PageError(f"cluster {i} of the page: decoded index {max(tri)} does not fit in a u8")
        order = decoding_order(safe, vc)
        c = {"indices": tri, "marks": marks[to:to + tc]}
        c["q"], nv, uv = rebuild_cluster(order, page, (pos, nrm if has_n else None, uvs if has_u else None))
        if has_n:
            c["normals"] = nv
        if has_u:
            c["uvs"] = uv
        if has_m:
            c["materials"] = mat[to:to + tc]
        out.append(c)
        to += tc
    return out


def source_vertices(clusters):
    """A decoded page's vertices in source numbering (section 4.3): cluster by
    cluster, each by vertex index, as (q, octahedral value, UV) tuples."""
    out = []
    for c in clusters:
        nv, uv = c.get("normals"), c.get("uvs")
        for v in range(len(c["q"])):
            out.append((c["q"][v], nv[v] if nv is not None else None, uv[v] if uv is not None else None))
    return out


def rebuild_cluster(order, page, residuals):
    """One cluster's values (grid coordinates, octahedral values, UVs; None
    for an attribute the file lacks) in decoding order (section 4.3): a copy
    (reference flag 1) takes every attribute of the vertex its target names, a
    far copy (flag 2) those of the source vertex its far target names, a
    stored vertex is its prediction plus its residuals. `page` carries the
    page's state from cluster to cluster."""
    vc = len(order)
    lanes = (3, 2, 2)
    wraps = (wrap32, wrap16, wrap16)
    values = [[None] * vc if res is not None else None for res in residuals]
    for v, pred in order:
        j = len(page["decoded"])
        if page["refs"][j] == 2:
            u = page["next_far"] + next(page["far"])
            if not 0 <= u < len(page["sources"]):
                raise PageError(f"vertex {j} of the page copies source vertex {u}, but its sources hold "
                                f"{len(page['sources'])}")
            page["next_far"] = u + 1
            for a in range(3):
                if values[a] is not None:
                    values[a][v] = list(page["sources"][u][a])
        elif page["refs"][j]:
            t = page["next_target"] + next(page["targets"])
            if not 0 <= t < j:
                raise PageError(f"vertex {j} of the page copies vertex {t}, not one decoded before it")
            page["next_target"] = t + 1
            for a in range(3):
                if values[a] is not None:
                    values[a][v] = list(page["decoded"][t][a])
        else:
            k = page["stored"]
            page["stored"] += 1
            for a in range(3):
                if values[a] is None:
                    continue
                w = lanes[a]
                r = residuals[a][w * k:w * k + w]
                if pred[0] == "par":
                    x, y, d = values[a][pred[1]], values[a][pred[2]], values[a][pred[3]]
                    p = [x[m] + y[m] - d[m] for m in range(w)]
                elif pred[0] == "vtx":
                    p = values[a][pred[1]]
                else:
                    p = page["anchor"][a]
                values[a][v] = [wraps[a](p[m] + r[m]) for m in range(w)]
        page["decoded"].append(tuple(values[a][v] if values[a] is not None else None for a in range(3)))
    first = order[0][0]
    page["anchor"] = tuple(values[a][first] if values[a] is not None else None for a in range(3))
    return values


def pack_bits(records, widths):
    """A bit stream (section 5.2) of records of fields with these widths."""
    acc = 0
    bit = 0
    for rec in records:
        for value, w in zip(rec, widths):
            acc |= value << bit
            bit += w
    return acc.to_bytes((bit + 31) // 32 * 4, "little")


def ranged(values, lanes):
    """(minimum, bits, bit stream) of values as offsets from their per-lane
    minimum (section 5: position_min/bits, normal_min/bits)."""
    lo = [min(v[k] for v in values) for k in range(lanes)]
    bits = [(max(v[k] for v in values) - lo[k]).bit_length() for k in range(lanes)]
    return lo, bits, pack_bits([[v[k] - lo[k] for k in range(lanes)] for v in values], bits)


def pad4(b):
    return b + b"\0" * (-len(b) % 4)


def gpu_layout(clusters, flags):
    """The GPU layout (section 5) of decoded clusters: headers, then every
    cluster's positions, normals, UVs, indices (+ open-edge block), materials."""
    heads = []
    blocks = []
    for c in clusters:
        vc, tc = len(c["q"]), len(c["indices"]) // 3
        pmin, pbits, pos = ranged(c["q"], 3)
        nmin, nbits, nrm = ([0, 0], [0, 0], None)
        if flags & FLAG_NORMALS:
            nmin, nbits, nrm = ranged(c["normals"], 2)
        uvs = b"".join(struct.pack("<HH", *uv) for uv in c["uvs"]) if flags & FLAG_UVS else None
        idx = bytes(x & 0xFF for x in c["indices"])
        edge_flags = EDGE_OPEN if any(c["marks"]) else 0
        if edge_flags:
            idx = pad4(idx) + pack_bits([[m] for m in c["marks"]], [3])
        mat = b"".join(struct.pack("<H", m) for m in c["materials"]) if flags & FLAG_MATERIALS else None
        heads.append((vc, tc, pmin, pbits, edge_flags, nmin, nbits))
        blocks.append([pos, nrm, uvs, idx, mat])
    at = CLUSTER_HEADER_SIZE * len(clusters)
    offsets = [[0] * 5 for _ in clusters]
    body = []
    for kind in range(5):
        for i, b in enumerate(blocks):
            if b[kind] is not None:
                offsets[i][kind] = at
                body.append(pad4(b[kind]))
                at += len(body[-1])
    out = []
    for (vc, tc, pmin, pbits, ef, nmin, nbits), offs in zip(heads, offsets):
        # a minimum outside i32 cannot be stored: the file is invalid
        if not all(-(1 << 31) <= x < (1 << 31) for x in pmin):
            raise PageError("a grid coordinate overflows i32")
        out.append(struct.pack("<HH3i3BB5I2H2BH", vc, tc, *pmin, *pbits, ef, *offs, *[x & 0xFFFF for x in nmin],
                               *[min(x, 255) for x in nbits], 0))
    return b"".join(out) + b"".join(body)


# ---------------------------------------------------------------------------
# layout pages (spec section 4.4): the GPU layout (section 5) in one LZ4 block
# ---------------------------------------------------------------------------

BLOCKS = ("positions_offset", "normals_offset", "uvs_offset", "indices_offset", "materials_offset")


def block_lengths(vc, tc, pbits, nbits, edge_flags, flags):
    """Padded lengths of a cluster's five blocks (section 5, in BLOCKS order;
    the indices block with its open-edge block, section 5.7) as its header's
    counts and bit widths give them; None for a block the flags leave out."""
    def words(bits):
        return (bits + 31) // 32 * 4
    marks = words(3 * tc) if edge_flags & EDGE_OPEN else 0
    return [words(vc * sum(pbits)),
            words(vc * sum(nbits)) if flags & FLAG_NORMALS else None,
            4 * vc if flags & FLAG_UVS else None,
            (3 * tc + 3) // 4 * 4 + marks,
            (2 * tc + 3) // 4 * 4 if flags & FLAG_MATERIALS else None]


def read_layout(raw, vcs, tcs, flags, normal_bits):
    """The clusters of a layout page (section 4.4) read from its GPU layout
    (section 5), as decode_encoded_page returns them. Checks what reading
    needs (headers against the records and the bit width limits, blocks
    inside the page, indices below vertex_count); whether the layout is the
    canonical one is left to canonical_values and gpu_layout. Raises PageError."""
    n = len(vcs)
    if len(raw) < CLUSTER_HEADER_SIZE * n:
        raise PageError(f"{n} cluster headers do not fit in its {len(raw)} bytes")
    heads = np.frombuffer(raw, CHDR_DT, count=n)
    words = np.frombuffer(pad4(raw) + bytes(8), "<u4")
    out = []
    for i, (h, vc, tc) in enumerate(zip(heads, vcs, tcs)):
        try:
            out.append(read_layout_cluster(raw, words, h, int(vc), int(tc), flags, normal_bits))
        except PageError as exc:
            raise PageError(f"cluster {i} of the page: {exc}") from None
    return out


def read_layout_cluster(raw, words, h, vc, tc, flags, normal_bits):
    """One cluster of a layout page: header h (section 5.1) and the blocks it
    points to (sections 5.2-5.8), every read inside the page."""
    if not (1 <= vc <= 256 and 1 <= tc <= 128):
        raise PageError(f"its record's counts {vc} vertices/{tc} triangles are outside 1..=256/1..=128")
    if (int(h["vertex_count"]), int(h["triangle_count"])) != (vc, tc):
        raise PageError(f"header counts {h['vertex_count']} vertices/{h['triangle_count']} triangles, its record "
                        f"says {vc}/{tc}")
    pbits, nbits, ef = h["position_bits"].tolist(), h["normal_bits"].tolist(), int(h["edge_flags"])
    has_n = bool(flags & FLAG_NORMALS)
    if max(pbits) > 32 or (has_n and max(nbits) > min(normal_bits, 16)):
        raise PageError(f"position_bits {pbits} over 32 or normal_bits {nbits} over the header's {normal_bits}")
    offs = [int(h[k]) for k in BLOCKS]
    for name, at, length in zip(BLOCKS, offs, block_lengths(vc, tc, pbits, nbits, ef, flags)):
        if length is not None and (at % 4 or at + length > len(raw)):
            raise PageError(f"{name} {at}: its {length}-byte block is not word-aligned or runs past the page's "
                            f"{len(raw)} bytes")
    c = {"q": bit_values(words, offs[0], vc, pbits, h["position_min"].tolist())}
    if has_n:
        c["normals"] = bit_values(words, offs[1], vc, nbits, h["normal_min"].tolist())
    if flags & FLAG_UVS:
        uv = struct.unpack_from(f"<{2 * vc}H", raw, offs[2])
        c["uvs"] = [list(uv[2 * v:2 * v + 2]) for v in range(vc)]
    c["indices"] = list(raw[offs[3]:offs[3] + 3 * tc])
    bad = [x for x in c["indices"] if x >= vc]
    if bad:
        raise PageError(f"index {bad[0]} >= vertex_count {vc}")
    c["marks"] = [0] * tc
    if ef & EDGE_OPEN:
        c["marks"] = [m[0] for m in bit_values(words, offs[3] + (3 * tc + 3) // 4 * 4, tc, [3], [0])]
    if flags & FLAG_MATERIALS:
        c["materials"] = list(struct.unpack_from(f"<{tc}H", raw, offs[4]))
    return c


def bit_values(words, offset, count, widths, minimum):
    """count records of len(widths) values from the bit stream (section 5.2)
    at byte `offset`, each value plus its lane's minimum (python ints)."""
    stride = sum(widths)
    out = np.empty((count, len(widths)), dtype=np.int64)
    at = np.arange(count, dtype=np.int64) * stride
    for k, w in enumerate(widths):
        out[:, k] = minimum[k] + read_bits(words, offset // 4, at, np.full(count, w, dtype=np.int64))
        at = at + w
    return out.tolist()


def canonical_values(clusters, normal_bits, flags):
    """What laying the values out again cannot see (section 4.4): vertices in
    first-use order, each triangle as the index codec gives it back (section
    4.3), octahedral values at most 2^normal_bits - 1 and grid coordinates
    within i32 (section 5.3). Raises PageError."""
    most = (1 << normal_bits) - 1
    for i, c in enumerate(clusters):
        where = f"cluster {i} of the page"
        vc, tri = len(c["q"]), c["indices"]
        if list(dict.fromkeys(tri + list(range(vc)))) != list(range(vc)):
            raise PageError(f"{where}: vertices are not numbered in first-use order")
        coded = meshopt.encode_index_buffer(np.array(tri, dtype=np.uint32))
        if meshopt.decode_index_buffer(coded, len(tri), 4).astype(np.int64).tolist() != tri:
            raise PageError(f"{where}: triangles are not as the index codec gives them back (corners rotated)")
        top = max((max(v) for v in c.get("normals") or ()), default=0)
        if flags & FLAG_NORMALS and top > most:
            raise PageError(f"{where}: octahedral value {top} over 2^normal_bits - 1 = {most}")
        if max((max(v) for v in c["q"]), default=0) >= 1 << 31:
            raise PageError(f"{where}: a grid coordinate overflows i32")


def count_frames(comp):
    """Number of concatenated zstd frames (informative)."""
    n = 0
    rest = comp
    dctx = zstandard.ZstdDecompressor()
    while rest:
        obj = dctx.decompressobj()
        obj.decompress(rest)
        n += 1
        rest = obj.unused_data
    return n


def fmt_f(x):
    return f"{float(x):.6g}"


# ---------------------------------------------------------------------------
# The checker
# ---------------------------------------------------------------------------

class Checker:
    def __init__(self, path, data, opts, report):
        self.path = path
        self.data = data
        self.opts = opts
        self.r = report
        self.t0 = time.perf_counter()
        self.timings = {}
        self.complete = False  # every cluster decoded without violation

    def _lap(self, name, start):
        self.timings[name] = round(time.perf_counter() - start, 3)

    # -- locations ---------------------------------------------------------
    def cl(self, c):
        """Human-readable location of cluster c."""
        s = f"cluster {c}"
        extra = []
        if self.cluster_refs_ok is not None and c < self.C:
            g = int(self.cgroup[c])
            if g < self.G:
                extra.append(f"group {g}")
            if self.cpage is not None:
                extra.append(f"page {int(self.cpage[c])}")
            elif g < self.G and self.gpage[g] < self.P:
                extra.append(f"page {int(self.gpage[g])}")
        return s + (f" ({', '.join(extra)})" if extra else "")

    def gl(self, g):
        return f"group {g} (level {int(self.glevel[g])}, page {int(self.gpage[g])})"

    # -- section 2 -----------------------------------------------------------
    def read_header(self):
        d = self.data
        n = len(d)
        r = self.r
        self.cluster_refs_ok = None
        self.cpage = None
        if n < HEADER_SIZE:
            r.fatal("truncated", f"file is {n} bytes, shorter than the {HEADER_SIZE}-byte header")
        (magic, version, header_size, flags, ox, oy, oz, step, umin0, umin1, uext0, uext1,
         normal_bits, position_bits, level_count, G, C, P, source_tris,
         h_off, h_size, pt_off, pt_size) = struct.unpack_from(HEADER_FMT, d, 0)
        if magic != MAGIC:
            r.fatal("bad_magic", f"magic is {magic!r}, expected {MAGIC!r}")
        if version in OLD_VERSIONS:
            r.fatal("bad_version", f"version {version}, this checker reads version {VERSION} only (version {version} "
                                   f"{OLD_VERSIONS[version]}; re-bake the mesh with the current baker)")
        if version != VERSION:
            r.fatal("bad_version", f"version {version}, this checker reads version {VERSION}")
        if header_size != HEADER_SIZE:
            r.fatal("bad_header_size", f"header_size {header_size} != {HEADER_SIZE}")
        if flags & ~KNOWN_FLAGS:
            r.violation("unknown_flags", f"flags 0x{flags:x} has unknown bits 0x{flags & ~KNOWN_FLAGS:x}")
        f32 = np.float32
        self.origin = np.array([ox, oy, oz], dtype=f32)
        self.step = f32(step)
        self.uv_min = np.array([umin0, umin1], dtype=f32)
        self.uv_extent = np.array([uext0, uext1], dtype=f32)
        if not np.isfinite(self.origin).all():
            r.violation("bad_quantization", f"grid_origin {self.origin.tolist()} is not finite")
        if not (math.isfinite(step) and step > 0):
            r.fatal("bad_quantization", f"grid_step {step} is not finite and > 0")
        if not np.isfinite(self.uv_min).all():
            r.violation("bad_quantization", f"uv_min {self.uv_min.tolist()} is not finite")
        if not (np.isfinite(self.uv_extent).all() and (self.uv_extent >= 0).all()):
            r.violation("bad_quantization", f"uv_extent {self.uv_extent.tolist()} is not finite and >= 0")
        if not 4 <= normal_bits <= 16:
            r.violation("bad_normal_bits", f"header normal_bits {normal_bits} outside 4..=16")
        self.flags = flags
        self.normal_bits = normal_bits
        self.position_bits = position_bits
        self.level_count = level_count
        self.G, self.C, self.P = G, C, P
        self.source_triangles = source_tris
        if h_off != HEADER_SIZE:
            r.fatal("section_layout", f"hierarchy_offset {h_off} != {HEADER_SIZE}")
        if h_size != G * GROUP_SIZE + C * CLUSTER_SIZE:
            r.fatal("section_layout", f"hierarchy_size {h_size} != G*40 + C*16 = "
                    f"{G * GROUP_SIZE + C * CLUSTER_SIZE} (G={G}, C={C})")
        if pt_off != h_off + h_size:
            r.fatal("section_layout", f"page_table_offset {pt_off} != hierarchy end {h_off + h_size}")
        if pt_size < P * PAGE_SIZE or (pt_size - P * PAGE_SIZE) % 4:
            r.fatal("section_layout", f"page_table_size {pt_size} is not P*72 + 4*D (P={P})")
        self.D = (pt_size - P * PAGE_SIZE) // 4
        self.pt_off = pt_off
        self.pt_end = pt_off + pt_size
        if n < self.pt_end:
            r.fatal("truncated", f"file is {n} bytes, shorter than the page table end {self.pt_end}")
        h = blake3.blake3(bytes(d[0:112]))
        h.update(bytes(d[HEADER_SIZE:self.pt_end]))
        if h.digest() != bytes(d[112:144]):
            r.violation("meta_checksum", "meta_checksum does not match BLAKE3(header[0..112] + hierarchy + page table)")
        if any(d[144:160]):
            r.violation("reserved_nonzero", "header reserved bytes 144..160 are not zero")
        if flags & FLAG_NORMALS and not 4 <= normal_bits <= 16:
            self.normals_decodable = False
        else:
            self.normals_decodable = True

    # -- section 3 and 4: parse --------------------------------------------------
    def read_tables(self):
        d, G, C, P = self.data, self.G, self.C, self.P
        g = np.frombuffer(d, GROUP_DT, count=G, offset=HEADER_SIZE)
        self.gcenter = g["center"].astype(np.float32).reshape(G, 3)
        self.gradius = g["radius"].astype(np.float32)
        self.gerror = g["error"].astype(np.float32)
        self.glevel = g["level"].astype(np.int64)
        self.gfirst = g["first_cluster"].astype(np.int64)
        self.gcount = g["cluster_count"].astype(np.int64)
        self.gpage = g["page"].astype(np.int64)
        self.greserved = g["reserved"].astype(np.int64)
        c = np.frombuffer(d, CLUSTER_DT, count=C, offset=HEADER_SIZE + G * GROUP_SIZE)
        self.cgroup = c["group"].astype(np.int64)
        self.cown = c["own_group"].astype(np.int64)
        self.cvc = c["vertex_count"].astype(np.int64)
        self.ctc = c["triangle_count"].astype(np.int64)
        self.cpoff = c["page_offset"].astype(np.int64)
        p = np.frombuffer(d, PAGE_DT, count=P, offset=self.pt_off)
        self.poff = p["offset"].astype(np.uint64)
        self.pcsize = p["compressed_size"].astype(np.int64)
        self.prsize = p["raw_size"].astype(np.int64)
        self.pchecksum = p["checksum"].copy()
        self.pfirst = p["first_cluster"].astype(np.int64)
        self.pcount = p["cluster_count"].astype(np.int64)
        self.pgfirst = p["first_group"].astype(np.int64)
        self.pgcount = p["group_count"].astype(np.int64)
        self.pdfirst = p["dependency_first"].astype(np.int64)
        self.pdcount = p["dependency_count"].astype(np.int64)
        self.deps = np.frombuffer(d, "<u4", count=self.D, offset=self.pt_off + P * PAGE_SIZE).astype(np.int64)

    # -- section 3: groups and clusters -------------------------------------------
    def check_groups(self):
        r, G, C, P = self.r, self.G, self.C, self.P
        bad_sphere = ~np.isfinite(self.gcenter).all(axis=1) | ~np.isfinite(self.gradius)
        r.violations_where("group_sphere", bad_sphere,
                           lambda g: f"group {g}: non-finite sphere centre {self.gcenter[g].tolist()} radius {self.gradius[g]}")
        neg_r = np.isfinite(self.gradius) & (self.gradius < 0)
        r.violations_where("group_sphere", neg_r, lambda g: f"group {g}: negative radius {self.gradius[g]}")
        bad_err = np.isnan(self.gerror) | (self.gerror < 0)
        r.violations_where("group_error", bad_err, lambda g: f"group {g}: error {self.gerror[g]} is NaN or negative")
        empty = self.gcount == 0
        r.violations_where("group_cluster_range", empty, lambda g: f"group {g}: cluster_count is 0")
        out = self.gfirst + self.gcount > C
        r.violations_where("group_cluster_range", out,
                           lambda g: f"group {g}: clusters {self.gfirst[g]}..{self.gfirst[g] + self.gcount[g]} beyond C={C}")
        bad_page = self.gpage >= P
        r.violations_where("group_page", bad_page, lambda g: f"group {g}: page {self.gpage[g]} >= P={P}")
        bad_level = self.glevel >= self.level_count
        r.violations_where("group_level", bad_level,
                           lambda g: f"group {g}: level {self.glevel[g]} >= level_count {self.level_count}")
        r.violations_where("reserved_nonzero", self.greserved != 0, lambda g: f"group {g}: reserved field is {self.greserved[g]}")
        if G and not bad_level.any() and self.level_count != int(self.glevel.max()) + 1:
            r.violation("level_count", f"level_count {self.level_count} != max group level + 1 = {int(self.glevel.max()) + 1}")
        if G == 0 and self.level_count != 0:
            r.note("level_count", f"no groups but level_count {self.level_count}")
        r.violations_where("group_order", np.flatnonzero(self.glevel[1:] > self.glevel[:-1]) + 1,
                           lambda g: f"group {g} (level {self.glevel[g]}) follows group {g - 1} (level {self.glevel[g - 1]}): "
                                     "groups must be stored coarse to fine (descending level)")
        self.group_ok = ~(bad_sphere | neg_r | bad_err | empty | out | bad_page | bad_level)
        self.gend = self.gfirst + self.gcount

    def check_clusters(self):
        r, G, C = self.r, self.G, self.C
        bad_group = self.cgroup >= G
        r.violations_where("cluster_group", bad_group, lambda c: f"cluster {c}: group {self.cgroup[c]} >= G={G}")
        self.has_own = self.cown != NONE
        bad_own = self.has_own & (self.cown >= G)
        r.violations_where("cluster_own_group", bad_own, lambda c: f"cluster {c}: own_group {self.cown[c]} >= G={G}")
        bad_vc = (self.cvc < 1) | (self.cvc > 256)
        r.violations_where("cluster_counts", bad_vc, lambda c: f"cluster {c}: vertex_count {self.cvc[c]} outside 1..=256")
        bad_tc = (self.ctc < 1) | (self.ctc > 128)
        r.violations_where("cluster_counts", bad_tc, lambda c: f"cluster {c}: triangle_count {self.ctc[c]} outside 1..=128")
        idx = np.arange(C, dtype=np.int64)
        if G:
            gsafe = np.where(bad_group, 0, self.cgroup)
            outside = ~bad_group & ((idx < self.gfirst[gsafe]) | (idx >= self.gend[gsafe]))
        else:
            outside = np.zeros(C, dtype=bool)
        r.violations_where("cluster_outside_group", outside,
                           lambda c: f"cluster {c}: not inside its group {self.cgroup[c]}'s range "
                                     f"{self.gfirst[self.cgroup[c]]}..{self.gend[self.cgroup[c]]}")
        # group ranges must cover every cluster exactly once (each cluster is a
        # member of exactly one group, the one its record names)
        ok = ~(self.gfirst + self.gcount > C)
        cov = np.zeros(C + 1, dtype=np.int64)
        np.add.at(cov, self.gfirst[ok], 1)
        np.add.at(cov, self.gend[ok], -1)
        cov = np.cumsum(cov)[:C]
        r.violations_where("group_ranges_coverage", cov != 1,
                           lambda c: f"cluster {c}: lies in {cov[c]} group ranges (must be exactly 1)")
        if G and ok.all():
            tiled = self.gfirst[0] == 0 and (self.gfirst[1:] == self.gend[:-1]).all() and self.gend[-1] == C
            if not tiled:
                r.note("group_ranges_order", "group cluster ranges do not follow group order (not required explicitly)")
        self.cluster_refs_ok = not (bad_group.any() or bad_own.any() or outside.any())
        self.cluster_ok = ~(bad_group | bad_own | bad_vc | bad_tc | outside)

    # -- section 4: pages ------------------------------------------------------
    def check_pages(self):
        r, G, C, P, D = self.r, self.G, self.C, self.P, self.D
        n = len(self.data)
        poff = self.poff.astype(np.float64)  # u64 may exceed int64
        end = poff + self.pcsize
        before = poff < self.pt_end
        r.violations_where("page_bytes", before,
                           lambda p: f"page {p}: offset {int(self.poff[p])} lies before the page data ({self.pt_end})")
        past = end > n
        r.violations_where("page_bytes", past,
                           lambda p: f"page {p}: bytes {int(self.poff[p])}..{int(self.poff[p]) + int(self.pcsize[p])} "
                                     f"lie outside the file ({n} bytes; truncated?)")
        big = self.prsize > MAX_RAW_SIZE
        r.violations_where("page_raw_size", big, lambda p: f"page {p}: raw_size {self.prsize[p]} > 16 MiB")
        bad_cr = self.pfirst + self.pcount > C
        r.violations_where("page_cluster_range", bad_cr,
                           lambda p: f"page {p}: clusters {self.pfirst[p]}..{self.pfirst[p] + self.pcount[p]} beyond C={C}")
        bad_gr = self.pgfirst + self.pgcount > G
        r.violations_where("page_group_range", bad_gr,
                           lambda p: f"page {p}: groups {self.pgfirst[p]}..{self.pgfirst[p] + self.pgcount[p]} beyond G={G}")
        bad_dr = self.pdfirst + self.pdcount > D
        r.violations_where("page_dependency_range", bad_dr,
                           lambda p: f"page {p}: dependencies {self.pdfirst[p]}..{self.pdfirst[p] + self.pdcount[p]} beyond D={D}")
        r.notes_where("empty_page", (self.pcount == 0) | (self.pgcount == 0),
                      lambda p: f"page {p}: {self.pcount[p]} clusters, {self.pgcount[p]} groups")
        self.page_ok = ~(before | past | big | bad_cr | bad_gr | bad_dr)
        # page bytes are stored in page order (section 1: "in page order")
        if P > 1:
            overlap = np.flatnonzero(poff[1:] < end[:-1]) + 1
            r.violations_where("page_order", overlap,
                               lambda p: f"page {p}: bytes start at {int(self.poff[p])}, before the end of page {p - 1} "
                                         f"({int(end[p - 1])}); page bytes must be stored in page order")
            gaps = np.flatnonzero(poff[1:] > end[:-1]) + 1
            r.notes_where("page_gap", gaps, lambda p: f"page {p}: {int(poff[p] - end[p - 1])} unused bytes before it")
        if P:
            if self.poff[0] != self.pt_end:
                r.note("page_gap", f"page 0 starts at {int(self.poff[0])}, page table ends at {self.pt_end}")
            last = int(end.max())
            if last < n:
                r.note("trailing_bytes", f"{n - last} bytes after the last page")
        # clusters are numbered page by page: page cluster ranges tile 0..C in order
        tiled = True
        if P:
            exp_first = np.concatenate([[0], np.cumsum(self.pcount)[:-1]])
            bad_tile = np.flatnonzero(self.pfirst != exp_first)
            r.violations_where("page_cluster_tiling", bad_tile,
                               lambda p: f"page {p}: first_cluster {self.pfirst[p]} but pages before it hold {exp_first[p]} clusters "
                                         "(clusters are numbered page by page)")
            if int(self.pcount.sum()) != C:
                r.violation("page_cluster_tiling", f"pages hold {int(self.pcount.sum())} clusters, C={C}")
                tiled = False
            tiled = tiled and bad_tile.size == 0
        elif C:
            r.violation("page_cluster_tiling", f"no pages but C={C}")
            tiled = False
        self.cpage = np.repeat(np.arange(P, dtype=np.int64), self.pcount) if tiled else None
        # each group lies in exactly one page's group range, and names that page
        okp = ~bad_gr
        cov = np.zeros(G + 1, dtype=np.int64)
        np.add.at(cov, self.pgfirst[okp], 1)
        np.add.at(cov, (self.pgfirst + self.pgcount)[okp], -1)
        cov = np.cumsum(cov)[:G]
        r.violations_where("page_group_coverage", cov != 1,
                           lambda g: f"group {g}: lies in {cov[g]} page group ranges (must be exactly 1)")
        if okp.all() and (cov == 1).all():
            owner = np.zeros(G, dtype=np.int64)
            order = np.argsort(self.pgfirst, kind="stable")
            for p in order:
                owner[self.pgfirst[p]:self.pgfirst[p] + self.pgcount[p]] = p
            r.violations_where("group_page", (owner != self.gpage),
                               lambda g: f"group {g}: record says page {self.gpage[g]} but page {owner[g]}'s group range holds it")
            if P and not (self.pgfirst == np.concatenate([[0], np.cumsum(self.pgcount)[:-1]])).all():
                r.violation("page_group_order", "page group ranges are not in page order (section 4.1: pages tile the groups in order)")
        # a group's clusters lie inside its page (section 7)
        gp_ok = self.group_ok & (self.gpage < P)
        gps = np.where(gp_ok, self.gpage, 0)
        if P:
            inside = (self.gfirst >= self.pfirst[gps]) & (self.gend <= self.pfirst[gps] + self.pcount[gps])
            r.violations_where("group_not_in_page", gp_ok & ~inside,
                               lambda g: f"group {g}: clusters {self.gfirst[g]}..{self.gend[g]} not inside page {self.gpage[g]}'s "
                                         f"clusters {self.pfirst[self.gpage[g]]}..{self.pfirst[self.gpage[g]] + self.pcount[self.gpage[g]]}")
        if self.cpage is not None:
            exp_off = CLUSTER_HEADER_SIZE * (np.arange(C, dtype=np.int64) - self.pfirst[self.cpage])
            r.violations_where("cluster_page_offset", self.cpoff != exp_off,
                               lambda c: f"{self.cl(c)}: page_offset {self.cpoff[c]} != 48*(index in page) = {exp_off[c]}")
            if self.cluster_refs_ok:
                gp = self.gpage[self.cgroup]
                r.violations_where("cluster_page", gp != self.cpage,
                                   lambda c: f"cluster {c}: stored in page {self.cpage[c]} but its group {self.cgroup[c]} "
                                             f"says page {gp[c]}")
        # coarse to fine: the first page holds a root group
        if P and G and not bad_gr[0]:
            gs = np.arange(self.pgfirst[0], self.pgfirst[0] + self.pgcount[0])
            if not np.isinf(self.gerror[gs]).any():
                r.note("first_page_root", "page 0 holds no root group (spec: pages are stored coarse to fine, root first)")

    def check_dependencies(self):
        r, P = self.r, self.P
        actual = set()
        for p in range(P):
            if self.pdfirst[p] + self.pdcount[p] > self.D:
                continue
            lst = self.deps[self.pdfirst[p]:self.pdfirst[p] + self.pdcount[p]]
            oor = lst >= P
            if oor.any():
                r.violation("dependency_range", f"page {p}: dependency {int(lst[oor][0])} >= P={P}", int(oor.sum()))
            if (lst == p).any():
                r.violation("dependency_self", f"page {p}: depends on itself")
            if lst.size > 1 and not (np.diff(lst) > 0).all():
                r.violation("dependency_order", f"page {p}: dependencies {lst[:8].tolist()}... not strictly ascending")
            for q in lst.tolist():
                actual.add((p, q))
        if P > 0 and self.P and self.pdcount.sum() and self.D:
            # dependency ranges tile the array in page order? (informative)
            exp = np.concatenate([[0], np.cumsum(self.pdcount)[:-1]])
            if not (self.pdfirst == exp).all() or int(self.pdcount.sum()) != self.D:
                r.note("dependency_layout", "dependency ranges do not tile the dependency array in page order")
        self.dep_actual = actual
        if self.cpage is None or not self.cluster_refs_ok or not (self.gpage < P).all():
            r.note("dependency_check_skipped", "expected dependencies not computed (earlier violations)")
            return
        expected = set()
        outs = np.flatnonzero(self.has_own)
        own = self.cown[outs]
        # outputs of p's groups: page of group own[c] depends on the page of c
        for a, b in set(zip(self.gpage[own].tolist(), self.cpage[outs].tolist())):
            if a != b:
                expected.add((a, b))
        # siblings: all output pages of one group depend on each other
        pages_of = {}
        for g, q in set(zip(own.tolist(), self.cpage[outs].tolist())):
            pages_of.setdefault(g, set()).add(q)
        for qs in pages_of.values():
            if len(qs) > 1:
                for a in qs:
                    for b in qs:
                        if a != b:
                            expected.add((a, b))
        missing = sorted(expected - actual)
        extra = sorted(actual - expected)
        for a, b in missing[:MAX_EXAMPLES]:
            r.violation("dependency_missing", f"page {a}: should depend on page {b} (parents or siblings of its clusters live there)", 0)
        if missing:
            r.violations["dependency_missing"]["count"] += len(missing)
        for a, b in extra[:MAX_EXAMPLES]:
            r.violation("dependency_extra", f"page {a}: depends on page {b}, which holds neither outputs of its groups "
                                            "nor siblings of its clusters", 0)
        if extra:
            r.violations["dependency_extra"]["count"] += len(extra)
        # dependencies on later pages break "a prefix is a usable coarse model" (informative)
        later = sum(1 for a, b in actual if b > a)
        if later:
            r.note("dependency_on_later_page", f"{later} dependencies point to later pages", later)
        self.r.figures["dependencies"] = len(actual)

    # -- section 6 invariants ------------------------------------------------
    def check_invariants(self):
        r, G = self.r, self.G
        if not self.cluster_refs_ok or not self.group_ok.all():
            r.note("invariants_skipped", "DAG invariants not checked (earlier violations in groups/clusters)")
            return
        ho = self.has_own
        own = np.where(ho, self.cown, 0)
        par = self.cgroup
        self.root = np.isposinf(self.gerror)
        nroots = int(self.root.sum())
        if nroots == 0:
            r.violation("no_root_group", "no group has error +inf")
        self.own_err = np.where(ho, self.gerror[own], np.float32(0))
        self.par_err = self.gerror[par]
        mono = ho & (self.par_err < self.own_err)
        r.violations_where("monotone_error", mono,
                           lambda c: f"{self.cl(c)}: parent group {par[c]} error {fmt_f(self.par_err[c])} < "
                                     f"own group {own[c]} error {fmt_f(self.own_err[c])}")
        cp = self.gcenter[par].astype(np.float64)
        co = self.gcenter[own].astype(np.float64)
        dist = np.sqrt(((cp - co) ** 2).sum(axis=1))
        rp = self.gradius[par].astype(np.float64)
        ro = self.gradius[own].astype(np.float64)
        slack = rp - (dist + ro)
        nested_bad = ho & (slack < 0)
        r.violations_where("nested_spheres", nested_bad,
                           lambda c: f"{self.cl(c)}: own group {own[c]} sphere (r={fmt_f(ro[c])}) not inside parent group "
                                     f"{par[c]} sphere (r={fmt_f(rp[c])}, centre distance {fmt_f(dist[c])}; "
                                     f"excess {fmt_f(-slack[c])})")
        dag_bad = ho & (self.glevel[own] >= self.glevel[par])
        r.violations_where("dag_order", dag_bad,
                           lambda c: f"{self.cl(c)}: own group {own[c]} level {self.glevel[own[c]]} >= "
                                     f"group {par[c]} level {self.glevel[par[c]]}")
        outputs = np.bincount(own[ho], minlength=G)
        r.violations_where("root_group_has_outputs", self.root & (outputs > 0),
                           lambda g: f"{self.gl(g)}: root group (error +inf) produced {outputs[g]} clusters")
        r.violations_where("group_without_outputs", ~self.root & (outputs == 0),
                           lambda g: f"{self.gl(g)}: finite error {fmt_f(self.gerror[g])} but no cluster has it as own_group")
        self.clevel = np.where(ho, self.glevel[own] + 1, 0)
        # level of a group vs. its members (informative: the spec only says a
        # group's level is the level "at which it was formed")
        maxmember = np.full(G, -1, dtype=np.int64)
        np.maximum.at(maxmember, par, self.clevel)
        r.notes_where("group_level_vs_members", maxmember != self.glevel,
                      lambda g: f"{self.gl(g)}: highest member level is {maxmember[g]}")
        minmember = np.full(G, 1 << 40, dtype=np.int64)
        np.minimum.at(minmember, par, self.clevel)
        r.notes_where("mixed_level_group", minmember != maxmember,
                      lambda g: f"{self.gl(g)}: member levels {minmember[g]}..{maxmember[g]}")
        self.outputs = outputs
        self.invariants_done = True
        # figures
        L = int(self.glevel.max()) + 1 if G else 0
        per_level = []
        for lv in range(max(L, int(self.clevel.max()) + 1 if self.C else 0)):
            m = self.clevel == lv
            per_level.append({"level": lv, "clusters": int(m.sum()), "groups": int((self.glevel == lv).sum()),
                              "triangles": int(self.ctc[m].sum())})
        f = r.figures
        f["levels"] = L
        f["per_level"] = per_level
        f["root_groups"] = nroots
        f["root_clusters"] = int(self.root[par].sum())
        l0 = self.clevel == 0
        f["level0_clusters"] = int(l0.sum())
        f["level0_triangles"] = int(self.ctc[l0].sum())
        f["level0_fill"] = float(self.ctc[l0].sum() / l0.sum()) if l0.any() else 0.0
        f["min_nested_slack"] = float(slack[ho].min()) if ho.any() else None

    # -- section 4.3 / 5: page contents ----------------------------------------------
    def decode_pages(self):
        r, C, P = self.r, self.C, self.P
        t = time.perf_counter()
        self.page_decoded = np.zeros(P, dtype=bool)
        decoded = [None] * P  # per page, its vertices in source numbering (for the pages that copy from it)
        chunks = []
        base = np.zeros(P, dtype=np.int64)
        hdr = np.zeros(C, dtype=CHDR_DT)
        have_hdr = np.zeros(C, dtype=bool)
        pos = 0
        frames = []
        layout = bool(self.flags & FLAG_LAYOUT_PAGES)
        for p in range(P):
            if not self.page_ok[p]:
                continue
            o = int(self.poff[p])
            comp = bytes(self.data[o:o + int(self.pcsize[p])])
            if blake3.blake3(comp).digest() != bytes(self.pchecksum[p]):
                r.violation("page_checksum", f"page {p}: BLAKE3 of its {len(comp)} compressed bytes does not match the page record")
                continue
            rs = int(self.prsize[p])
            first, n = int(self.pfirst[p]), int(self.pcount[p])
            vcs, tcs = self.cvc[first:first + n], self.ctc[first:first + n]
            if layout:
                got = self.decode_layout_page(p, comp, rs, vcs, tcs)
            else:
                got = self.decode_compact_page(p, comp, vcs, tcs, decoded)
            if got is None:
                continue
            clusters, raw = got
            if len(raw) != rs:
                r.violation("page_raw_size", f"page {p}: decodes to a {len(raw)}-byte GPU layout, raw_size says {rs}")
                continue
            if not layout and len(frames) < 64:
                frames.append(count_frames(comp))
            if CLUSTER_HEADER_SIZE * n > rs:
                r.violation("page_headers", f"page {p}: {n} cluster headers do not fit in {rs} bytes")
                continue
            hdr[first:first + n] = np.frombuffer(raw, CHDR_DT, count=n)
            have_hdr[first:first + n] = True
            self.page_decoded[p] = True
            decoded[p] = source_vertices(clusters)
            base[p] = pos
            pad = (-len(raw)) % 4
            chunks.append(raw)
            if pad:
                chunks.append(b"\0" * pad)
            pos += len(raw) + pad
        chunks.append(b"\0" * 8)
        buf = b"".join(chunks)
        self.bytes_arr = np.frombuffer(buf, dtype=np.uint8)
        self.words = np.frombuffer(buf, dtype="<u4")
        self.page_base = base
        self.hdr = hdr
        self.have_hdr = have_hdr
        r.figures["page_encoding"] = "layout" if layout else "compact"
        if not layout:
            r.figures["zstd_frames_per_page"] = sorted(set(frames))
        self._lap("decompress", t)

    def decode_compact_page(self, p, comp, vcs, tcs, decoded):
        """Page p's clusters and GPU layout from its zstd frames (section 4.3),
        `decoded` holding its sources' vertices; None after a violation."""
        r = self.r
        most = max_encoded_len(self.flags, vcs, tcs)
        if most > MAX_ENCODED_SIZE:
            r.violation("page_encoding", f"page {p}: its clusters could encode to {most} bytes (limit 32 MiB)")
            return None
        try:
            enc = decompress_frames(comp, most)
        except zstandard.ZstdError as exc:
            r.violation("page_decompress", f"page {p}: zstd error: {exc}")
            return None
        if len(enc) > most:
            r.violation("page_decompress", f"page {p}: decompresses to more than the {most} bytes its counts allow")
            return None
        sources = self.page_sources(p)
        missing = [q for q in sources if decoded[q] is None]
        if missing:
            r.violation("page_encoding", f"page {p}: its source page {missing[0]} (an earlier dependency it may "
                                         "copy vertices from) did not decode")
            return None
        source_list = [v for q in sources for v in decoded[q]]
        try:
            clusters = decode_encoded_page(enc, vcs, tcs, self.flags, source_list)
            return clusters, gpu_layout(clusters, self.flags)
        except PageError as exc:
            r.violation("page_encoding", f"page {p}: {exc}")
            return None

    def decode_layout_page(self, p, comp, rs, vcs, tcs):
        """Page p's clusters and GPU layout from its LZ4 block (section 4.4):
        exactly raw_size bytes, read back into values (read_layout) that lay
        out again to the same bytes (the canonical layout); None after a
        violation."""
        r = self.r
        bound = rs + rs // 255 + 16  # LZ4_compressBound (section 4.4)
        if len(comp) > bound:
            r.violation("page_decompress", f"page {p}: an LZ4 block of {len(comp)} bytes for {rs} bytes of layout (at most {bound})")
            return None
        try:
            raw = lz4.block.decompress(comp, uncompressed_size=rs)
        except lz4.block.LZ4BlockError as exc:
            r.violation("page_decompress", f"page {p}: LZ4 error: {exc}")
            return None
        if len(raw) != rs:
            r.violation("page_decompress", f"page {p}: its LZ4 block decompresses to {len(raw)} bytes, raw_size says {rs}")
            return None
        try:
            clusters = read_layout(raw, vcs, tcs, self.flags, self.normal_bits)
            canonical_values(clusters, self.normal_bits, self.flags)
            again = gpu_layout(clusters, self.flags)
        except PageError as exc:
            r.violation("page_layout", f"page {p}: {exc}")
            return None
        if again != raw:
            at = next((i for i, (a, b) in enumerate(zip(again, raw)) if a != b), min(len(again), len(raw)))
            r.violation("page_layout", f"page {p}: not the canonical layout of its values (first differing byte {at})")
            return None
        return clusters, raw

    def page_sources(self, p):
        """Page p's sources (section 4.3): its dependencies before it, in the
        array's order (none where its dependency range is out of bounds, and
        none in a file of layout pages, which decode alone: section 4.4)."""
        first, count = int(self.pdfirst[p]), int(self.pdcount[p])
        if first + count > self.D or self.flags & FLAG_LAYOUT_PAGES:
            return []
        return [int(q) for q in self.deps[first:first + count] if q < p]

    def check_cluster_headers(self):
        r, C = self.r, self.C
        h = self.hdr
        if self.cpage is None:
            self.hdr_ok = np.zeros(C, dtype=bool)
            self.has_marks = np.zeros(C, dtype=bool)
            return
        have = self.have_hdr
        page = self.cpage
        rsize = self.prsize[page]
        hdr_end = CLUSTER_HEADER_SIZE * self.pcount[page]
        vc = h["vertex_count"].astype(np.int64)
        tc = h["triangle_count"].astype(np.int64)
        cnt_bad = have & ((vc != self.cvc) | (tc != self.ctc))
        r.violations_where("cluster_header_counts", cnt_bad,
                           lambda c: f"{self.cl(c)}: header counts {vc[c]} vertices/{tc[c]} triangles, record says "
                                     f"{self.cvc[c]}/{self.ctc[c]}")
        pb = h["position_bits"].astype(np.int64)
        pb_bad = have & (pb > 32).any(axis=1)
        r.violations_where("cluster_position_bits", pb_bad, lambda c: f"{self.cl(c)}: position_bits {pb[c].tolist()} > 32")
        res_bad = have & (h["reserved1"] != 0)
        r.violations_where("reserved_nonzero", res_bad, lambda c: f"{self.cl(c)}: cluster header reserved field not zero")
        ef = h["edge_flags"].astype(np.int64)
        ef_bad = have & ((ef & ~EDGE_OPEN) != 0)
        r.violations_where("cluster_edge_flags", ef_bad,
                           lambda c: f"{self.cl(c)}: edge_flags 0x{ef[c]:02x} has bits other than bit 0 (OPEN_EDGES)")
        self.has_marks = have & ((ef & EDGE_OPEN) != 0)
        nb = h["normal_bits"].astype(np.int64)
        has_n = bool(self.flags & FLAG_NORMALS)
        nb_bad = have & has_n & (nb > self.normal_bits).any(axis=1)
        r.violations_where("cluster_normal_bits", nb_bad,
                           lambda c: f"{self.cl(c)}: normal_bits {nb[c].tolist()} > header normal_bits {self.normal_bits}")
        bad = cnt_bad | pb_bad | nb_bad | ef_bad
        lengths = {
            "positions_offset": (True, (vc * pb.sum(axis=1) + 31) // 32 * 4),
            "normals_offset": (has_n, (vc * nb.sum(axis=1) + 31) // 32 * 4),
            "uvs_offset": (bool(self.flags & FLAG_UVS), 4 * vc),
            "indices_offset": (True, 3 * tc),
            "materials_offset": (bool(self.flags & FLAG_MATERIALS), 2 * tc),
        }
        blocks = []
        for name, (present, length) in lengths.items():
            off = h[name].astype(np.int64)
            if present:
                miss = have & (off == 0)
                r.violations_where("cluster_block_presence", miss, lambda c, n=name: f"{self.cl(c)}: {n} is 0 (block absent) "
                                   "but the block is required")
            else:
                miss = have & (off != 0)
                r.violations_where("cluster_block_presence", miss, lambda c, n=name: f"{self.cl(c)}: {n} is {off[c]} "
                                   "but the header flag for this block is not set")
            align = have & (off % 4 != 0)
            r.violations_where("cluster_block_alignment", align, lambda c, n=name: f"{self.cl(c)}: {n} {off[c]} not a multiple of 4")
            bounds = have & present & (off != 0) & ((off < hdr_end) | (off + length > rsize))
            r.violations_where("cluster_block_bounds", bounds,
                               lambda c, n=name: f"{self.cl(c)}: {n} block {off[c]}..{off[c] + length[c]} not inside the page's "
                                                 f"data area {hdr_end[c]}..{rsize[c]}")
            bad |= miss | align | bounds
            if present:
                blocks.append((off, length))
        # the open-edge block (section 5.7): no offset field, right after the
        # indices block's padding, 3 bits per triangle in whole words
        self.marks_offset = h["indices_offset"].astype(np.int64) + (3 * tc + 3) // 4 * 4
        self.marks_length = (3 * tc + 31) // 32 * 4
        mo, ml = self.marks_offset, self.marks_length
        marks_out = self.has_marks & ~bad & (mo + ml > rsize)
        r.violations_where("open_edge_block_bounds", marks_out,
                           lambda c: f"{self.cl(c)}: open-edge block {mo[c]}..{mo[c] + ml[c]} runs past the page's "
                                     f"{rsize[c]} bytes")
        bad |= marks_out
        ok = have & ~bad
        bad |= self.check_block_overlap(ok & self.has_marks, ok, blocks, page)
        self.hdr_ok = have & ~bad & self.cluster_ok

    def check_block_overlap(self, marked, ok, blocks, page):
        """Open-edge blocks must not overlap any block of their page (a violation,
        section 5.7); other blocks overlapping each other is informative. Returns
        the clusters whose open-edge block overlaps another block."""
        r, C = self.r, self.C
        bad = np.zeros(C, dtype=bool)
        cs = np.flatnonzero(ok)
        mk = np.flatnonzero(marked)
        if not cs.size:
            return bad
        starts = np.concatenate([b[0][cs] for b in blocks] + [self.marks_offset[mk]])
        ends = np.concatenate([b[0][cs] + b[1][cs] for b in blocks] + [self.marks_offset[mk] + self.marks_length[mk]])
        pg = np.concatenate([np.tile(page[cs], len(blocks)), page[mk]])
        owner = np.concatenate([np.tile(cs, len(blocks)), mk])
        is_marks = np.concatenate([np.zeros(cs.size * len(blocks), dtype=bool), np.ones(mk.size, dtype=bool)])
        nonempty = ends > starts
        starts, ends, pg, owner, is_marks = (a[nonempty] for a in (starts, ends, pg, owner, is_marks))
        order = np.lexsort((starts, pg))
        s, e, q, o, m = starts[order], ends[order], pg[order], owner[order], is_marks[order]
        big = np.int64(1 << 26)  # > any offset in a page: keeps the running maximum per page
        # block i overlaps an earlier one iff it starts before the largest end so far
        # in its page, and a later one iff the next block of its page starts before it ends
        prev_end = np.maximum.accumulate(e + q * big)
        hits_prev = np.zeros(s.size, dtype=bool)
        hits_prev[1:] = (q[1:] == q[:-1]) & (s[1:] + q[1:] * big < prev_end[:-1])
        hits_next = np.zeros(s.size, dtype=bool)
        hits_next[:-1] = (q[1:] == q[:-1]) & (s[1:] < e[:-1])
        r.notes_where("block_overlap", hits_prev & ~m,
                      lambda i: f"page {q[i]}: block of cluster {o[i]} at {s[i]} overlaps an earlier block")
        ov = (hits_prev | hits_next) & m
        r.violations_where("open_edge_block_overlap", ov,
                           lambda i: f"page {q[i]}: open-edge block of cluster {o[i]} at {s[i]}..{e[i]} overlaps "
                                     "another block of the page")
        bad[o[ov]] = True
        return bad

    def decode_clusters(self):
        """Decode positions, normals, UVs, indices and materials of every
        cluster whose header passed (vectorized over all clusters)."""
        r, C = self.r, self.C
        t = time.perf_counter()
        h = self.hdr
        ok = self.hdr_ok
        cs = np.flatnonzero(ok)
        vc = np.where(ok, self.cvc, 0)
        tc = np.where(ok, self.ctc, 0)
        self.vbase = np.concatenate([[0], np.cumsum(vc)])
        self.tbase = np.concatenate([[0], np.cumsum(tc)])
        page = self.cpage if self.cpage is not None else np.zeros(C, dtype=np.int64)
        cbase = self.page_base[page] if self.P else np.zeros(C, dtype=np.int64)
        vcl = np.repeat(np.arange(C, dtype=np.int64), vc)  # cluster of each vertex
        vloc = seg_arange(vc)                                 # vertex index in cluster
        words = self.words
        # positions
        pb = h["position_bits"].astype(np.int64)
        stride = pb.sum(axis=1)
        w0 = (cbase + h["positions_offset"].astype(np.int64)) // 4
        pmin = h["position_min"].astype(np.int64)
        q = np.empty((vcl.size, 3), dtype=np.int64)
        pref = 0
        for k in range(3):
            bit = vloc * stride[vcl] + (pref if isinstance(pref, int) else pref[vcl])
            q[:, k] = pmin[vcl, k] + read_bits(words, w0[vcl], bit, pb[vcl, k])
            pref = pb[:, 0] if k == 0 else pb[:, 0] + pb[:, 1]
        over = (q < -(1 << 31)) | (q >= (1 << 31))
        if over.any():
            vs = np.flatnonzero(over.any(axis=1))
            r.violations_where("position_overflow", vs,
                               lambda v: f"{self.cl(vcl[v])}: vertex {vloc[v]} grid coordinate {q[v].tolist()} overflows i32")
        if cs.size:
            mins = np.minimum.reduceat(q, self.vbase[cs], axis=0) if vcl.size else np.zeros((0, 3))
            bad = np.flatnonzero((mins - pmin[cs] != 0).any(axis=1))
            r.violations_where("position_min", cs[bad],
                               lambda c: f"{self.cl(c)}: position_min {pmin[c].tolist()} but the smallest decoded grid "
                                         f"coordinates are {mins[np.searchsorted(cs, c)].tolist()}")
        self.q = q
        self.vcl = vcl
        # object-space positions, f32: origin + f32(q) * step
        self.pos = self.origin[None, :] + q.astype(np.float32) * self.step
        # normals
        if self.flags & FLAG_NORMALS and self.normals_decodable and vcl.size:
            nb = h["normal_bits"].astype(np.int64)
            nmin = h["normal_min"].astype(np.int64)
            w0 = (cbase + h["normals_offset"].astype(np.int64)) // 4
            nst = nb.sum(axis=1)
            a = nmin[vcl, 0] + read_bits(words, w0[vcl], vloc * nst[vcl], nb[vcl, 0])
            b = nmin[vcl, 1] + read_bits(words, w0[vcl], vloc * nst[vcl] + nb[vcl, 0], nb[vcl, 1])
            M = (1 << self.normal_bits) - 1
            rng_bad = np.flatnonzero((a > M) | (b > M))
            r.violations_where("normal_range", rng_bad,
                               lambda v: f"{self.cl(vcl[v])}: vertex {vloc[v]} octahedral value ({a[v]}, {b[v]}) > {M}")
            if cs.size:
                ab = np.stack([a, b], axis=1)
                mins = np.minimum.reduceat(ab, self.vbase[cs], axis=0)
                bad = np.flatnonzero((mins != nmin[cs]).any(axis=1))
                r.violations_where("normal_min", cs[bad],
                                   lambda c: f"{self.cl(c)}: normal_min {nmin[c].tolist()} but the smallest decoded values are "
                                             f"{mins[np.searchsorted(cs, c)].tolist()}")
            f32 = np.float32
            Mf = f32(M)
            x = a.astype(f32) / Mf * f32(2) - f32(1)
            y = b.astype(f32) / Mf * f32(2) - f32(1)
            z = f32(1) - np.abs(x) - np.abs(y)
            sx = np.where(x >= 0, f32(1), f32(-1))
            sy = np.where(y >= 0, f32(1), f32(-1))
            fold = z < 0
            x2 = np.where(fold, (f32(1) - np.abs(y)) * sx, x)
            y2 = np.where(fold, (f32(1) - np.abs(x)) * sy, y)
            nrm = np.stack([x2, y2, z], axis=1)
            length = np.sqrt((nrm * nrm).sum(axis=1))
            with np.errstate(invalid="ignore", divide="ignore"):
                nrm = nrm / length[:, None]
            r.violations_where("normal_decode", ~np.isfinite(nrm).all(axis=1),
                               lambda v: f"{self.cl(vcl[v])}: vertex {vloc[v]} normal does not decode to a unit vector")
            self.normals = nrm
        # UVs
        bytes_arr = self.bytes_arr
        if self.flags & FLAG_UVS and vcl.size:
            p0 = cbase[vcl] + h["uvs_offset"].astype(np.int64)[vcl] + 4 * vloc
            u = bytes_arr[p0].astype(np.int64) | (bytes_arr[p0 + 1].astype(np.int64) << 8)
            v = bytes_arr[p0 + 2].astype(np.int64) | (bytes_arr[p0 + 3].astype(np.int64) << 8)
            uv = np.stack([u, v], axis=1).astype(np.float32)
            self.uvs = self.uv_min[None, :] + (uv / np.float32(65535)) * self.uv_extent[None, :]
            r.violations_where("uv_decode", ~np.isfinite(self.uvs).all(axis=1),
                               lambda i: f"{self.cl(vcl[i])}: vertex {vloc[i]} UV is not finite")
        # indices
        ncorner = 3 * tc
        ccl = np.repeat(np.arange(C, dtype=np.int64), ncorner)
        cloc = seg_arange(ncorner)
        idx = bytes_arr[cbase[ccl] + h["indices_offset"].astype(np.int64)[ccl] + cloc].astype(np.int64)
        ib = np.flatnonzero(idx >= vc[ccl])
        r.violations_where("index_out_of_range", ib,
                           lambda i: f"{self.cl(ccl[i])}: triangle {cloc[i] // 3} index {idx[i]} >= vertex_count {vc[ccl[i]]}")
        self.indices_ok = ib.size == 0
        self.tri_local = idx.reshape(-1, 3)
        self.tcl = np.repeat(np.arange(C, dtype=np.int64), tc)
        tl = self.tri_local
        degen = (tl[:, 0] == tl[:, 1]) | (tl[:, 1] == tl[:, 2]) | (tl[:, 0] == tl[:, 2])
        r.notes_where("degenerate_index_triangle", degen,
                      lambda i: f"{self.cl(self.tcl[i])}: triangle {i - self.tbase[self.tcl[i]]} repeats a vertex index")
        self.decode_marks(cbase, tc)
        # materials
        if self.flags & FLAG_MATERIALS and tc.sum():
            tloc = seg_arange(tc)
            p0 = cbase[self.tcl] + h["materials_offset"].astype(np.int64)[self.tcl] + 2 * tloc
            mat = bytes_arr[p0].astype(np.int64) | (bytes_arr[p0 + 1].astype(np.int64) << 8)
            self.materials = mat
            r.figures["materials"] = np.unique(mat).tolist()[:64]
        vertex_unused = np.ones(vcl.size, dtype=bool)
        if self.indices_ok and vcl.size:
            vertex_unused[self.vbase[self.tcl][:, None] + tl] = False
            r.notes_where("unreferenced_vertex", vertex_unused,
                          lambda v: f"{self.cl(vcl[v])}: vertex {vloc[v]} is not used by any triangle")
        self.complete = bool(ok.all() and self.indices_ok and not over.any() and C > 0)
        self._lap("decode", t)

    def decode_marks(self, cbase, tc):
        """Open-edge marks (section 5.7): self.marks[t, k] is True iff the edge of
        triangle t from corner k to corner (k+1) mod 3 is marked."""
        C = self.C
        self.marks = np.zeros((int(tc.sum()), 3), dtype=bool)
        flagged = self.has_marks & (tc > 0)
        if not flagged.any():
            return
        w0 = (cbase + self.marks_offset) // 4
        tri = np.flatnonzero(flagged[self.tcl])              # triangles of flagged clusters
        c = self.tcl[tri]
        tloc = tri - self.tbase[c]
        value = read_bits(self.words, w0[c], 3 * tloc, np.full(tri.size, 3, dtype=np.int64))
        self.marks[tri] = (value[:, None] >> np.arange(3)) & 1 == 1
        # unused high bits of the last word are zero
        fc = np.flatnonzero(flagged)
        used = 3 * tc[fc]
        rest = (32 - used % 32) % 32
        tail = read_bits(self.words, w0[fc], used, rest)
        self.r.violations_where("open_edge_unused_bits", fc[tail != 0],
                                lambda i: f"{self.cl(i)}: open-edge block has nonzero unused bits after its "
                                          f"{3 * tc[i]} mark bits")
        self.r.notes_where("open_edge_block_empty", fc[~np.bincount(c, weights=value, minlength=C)[fc].astype(bool)],
                           lambda i: f"{self.cl(i)}: edge_flags announces an open-edge block but no edge is marked")
        self.r.figures["marked_uses"] = int(self.marks.sum())
        self.r.figures["clusters_with_marks"] = int(fc.size)

    # -- welding and edges ----------------------------------------------------
    def build_topology(self):
        t = time.perf_counter()
        q = self.q
        lo = q.min(axis=0)
        span = q.max(axis=0) - lo + 1
        if float(span[0]) * float(span[1]) * float(span[2]) < 2.0 ** 62:
            key = ((q[:, 0] - lo[0]) * span[1] + (q[:, 1] - lo[1])) * span[2] + (q[:, 2] - lo[2])
            _, first, wid = np.unique(key, return_index=True, return_inverse=True)
        else:
            qc = np.ascontiguousarray(q)
            _, first, wid = np.unique(qc, axis=0, return_index=True, return_inverse=True)
        wid = wid.reshape(-1)
        self.NW = int(first.size)
        self.wq = q[first]                     # grid coordinate of each welded vertex
        # trimesh meshes are built in grid units (distances x grid_step = object
        # space): trimesh's closest-point code uses absolute tolerances (1e-12 on
        # squared lengths) that give wrong answers for triangles of ~1e-3 size.
        self.qcentre = np.round((self.wq.min(axis=0) + self.wq.max(axis=0)) / 2)
        self.wgrid = (self.wq - self.qcentre).astype(np.float64)
        tw = wid[self.vbase[self.tcl][:, None] + self.tri_local]
        self.tw = tw
        degen = (tw[:, 0] == tw[:, 1]) | (tw[:, 1] == tw[:, 2]) | (tw[:, 0] == tw[:, 2])
        self.r.notes_where("degenerate_welded_triangle", degen,
                           lambda i: f"{self.cl(self.tcl[i])}: triangle {i - self.tbase[self.tcl[i]]} has two vertices "
                                     "with the same grid coordinate")
        a = tw
        b = tw[:, [1, 2, 0]]
        elo = np.minimum(a, b)
        ehi = np.maximum(a, b)
        ekey = elo * self.NW + ehi
        ukeys, eid = np.unique(ekey.reshape(-1), return_inverse=True)
        self.eid = eid.reshape(-1, 3)
        self.E = int(ukeys.size)
        self.ekeys = ukeys
        level0 = self.clevel == 0
        self.tri_l0 = level0[self.tcl]
        # a use of an edge is numbered by the edge, plus E where the triangle marks
        # it: one bincount of 2E bins gives the unmarked (first E) and marked uses
        self.euse = self.eid + self.E * self.marks
        self.U0, self.M0 = self.use_counts(self.tri_l0)
        self.L0 = self.U0 + self.M0
        self.special = (self.L0 > 0) & (self.L0 != 2)
        f = self.r.figures
        f["welded_vertices"] = self.NW
        f["level0_boundary_edges"] = int((self.L0 == 1).sum())
        f["level0_nonmanifold_edges"] = int((self.L0 > 2).sum())
        f["level0_marked_edges"] = int((self.M0 > 0).sum())
        self._lap("topology", t)

    def use_counts(self, tri_mask):
        """(U, M): unmarked and marked uses of every edge by the triangles in tri_mask."""
        cnt = np.bincount(self.euse[tri_mask].reshape(-1), minlength=2 * self.E)
        return cnt[:self.E], cnt[self.E:]

    def edge_desc(self, e):
        k = int(self.ekeys[e])
        a, b = divmod(int(k), self.NW)
        return f"edge {self.wq[a].tolist()}-{self.wq[b].tolist()}"

    def edge_users(self, e, tri_mask):
        """The clusters among tri_mask's triangles that use edge e, with their
        unmarked and marked uses (for messages)."""
        t, k = np.nonzero((self.eid == e) & tri_mask[:, None])
        cs = self.tcl[t]
        out = []
        for c in np.unique(cs)[:4].tolist():
            mk = self.marks[t[cs == c], k[cs == c]]
            out.append(f"{self.cl(c)} ({int((~mk).sum())} unmarked, {int(mk.sum())} marked)")
        more = np.unique(cs).size - len(out)
        return "; ".join(out) + (f"; {more} more" if more > 0 else "") if out else "none"

    # -- section 6, crack-free cuts: marks of level 0 and of each group -------------
    def check_marks(self):
        """Rule (a): at level 0 an edge carries exactly one mark iff it is used an
        odd number of times. Rule (b): each finite-error group keeps its border
        (the edges its members use an odd number of times unmarked are those its
        outputs do) and its outputs mark an edge at most once."""
        t0 = time.perf_counter()
        r = self.r
        bad = self.M0 != (self.L0 & 1)
        r.violations_where("level0_marks", bad,
                           lambda e: f"rule (a): {self.edge_desc(e)} is used {self.L0[e]} times at level 0, "
                                     f"{self.M0[e]} of them marked (must be {self.L0[e] & 1}); level-0 clusters using it: "
                                     f"{self.edge_users(e, self.tri_l0)}")
        self.check_group_marks()
        self._lap("marks", t0)

    def group_edge_uses(self, group_of_cluster, marked):
        """Sorted keys g*E + e and their counts, over the edge uses with the given
        mark state by clusters whose group_of_cluster is a finite-error group g."""
        uc = np.repeat(self.tcl, 3)
        g = group_of_cluster[uc]
        valid = (g >= 0) & (g < self.G)
        valid[valid] = np.isfinite(self.gerror[g[valid]])
        sel = valid & (self.marks.reshape(-1) == marked)
        return np.unique(g[sel] * self.E + self.eid.reshape(-1)[sel], return_counts=True)

    def check_group_marks(self):
        r, E = self.r, self.E
        own = np.where(self.has_own, self.cown, -1)
        kin, nin = self.group_edge_uses(self.cgroup, False)
        kout, nout = self.group_edge_uses(own, False)
        odd_in = kin[(nin & 1) == 1]
        odd_out = kout[(nout & 1) == 1]
        lost = np.setdiff1d(odd_in, odd_out, assume_unique=True)   # border edge the outputs do not keep
        new = np.setdiff1d(odd_out, odd_in, assume_unique=True)    # odd unmarked edge the members do not have
        for kind, keys, what in (("group_border_lost", lost, "its members use it an odd number of times unmarked, "
                                                              "its outputs an even number"),
                                 ("group_border_new", new, "its outputs use it an odd number of times unmarked, "
                                                           "its members an even number")):
            r.violations_where(kind, np.arange(keys.size),
                               lambda i, keys=keys, what=what: self.group_edge_msg(int(keys[i]), what))
        kmk, nmk = self.group_edge_uses(own, True)
        twice = kmk[nmk > 1]
        r.violations_where("group_marked_twice", np.arange(twice.size),
                           lambda i: self.group_edge_msg(int(twice[i]), "its outputs mark it more than once"))
        f = r.figures
        f["group_border_edges"] = int(odd_in.size)

    def group_edge_msg(self, key, what):
        g, e = divmod(key, self.E)
        members = np.repeat(self.cgroup == g, np.where(self.hdr_ok, self.ctc, 0))
        outputs = np.repeat(self.has_own & (self.cown == g), np.where(self.hdr_ok, self.ctc, 0))
        return (f"rule (b): {self.gl(g)}, {self.edge_desc(e)}: {what}; members using it: "
                f"{self.edge_users(e, members)}; outputs using it: {self.edge_users(e, outputs)}")

    # Section 6, rule (c): in every cut an edge's unmarked uses are even (twice,
    # or four times where simplification pinched a thin part into one edge), and
    # at most one use is marked. Odd unmarked = hole or T-junction.
    @staticmethod
    def bad_edges(U, M):
        return ((U & 1) == 1) | (M > 1)

    def pinched_edges(self, U):
        return ~self.special & (U >= 4)

    def describe_cut_failure(self, name, sel, U, M, bad):
        odd = np.flatnonzero(bad & ((U & 1) == 1))
        twice = np.flatnonzero(bad & (M > 1))
        tm = self.cluster_tris_mask(sel)
        examples = []
        for edges, why in ((odd, "unmarked uses must be even: a hole or T-junction"),
                           (twice, "at most one use may be marked")):
            if edges.size:
                e = int(edges[0])
                examples.append(f"{self.edge_desc(e)} used {U[e]} times unmarked and {M[e]} marked ({why}; level 0: "
                                f"{self.U0[e]} unmarked, {self.M0[e]} marked); cut clusters using it: "
                                f"{self.edge_users(e, tm)}; level-0 clusters using it: {self.edge_users(e, self.tri_l0)}")
        return (f"{name}: rule (c) broken: {odd.size} edges used an odd number of times unmarked, {twice.size} marked "
                f"more than once; e.g. " + "; and ".join(examples))

    def cluster_tris_mask(self, sel):
        return np.repeat(sel, np.where(self.hdr_ok, self.ctc, 0))

    def check_overlap(self, name, sel):
        """Section 6: no selected cluster is a member of the group that produced
        another selected cluster."""
        produced = np.zeros(self.G, dtype=bool)
        produced[self.cown[sel & self.has_own]] = True
        bad = sel & produced[self.cgroup]
        if bad.any():
            c = int(np.flatnonzero(bad)[0])
            g = int(self.cgroup[c])
            x = int(np.flatnonzero(sel & (self.cown == g))[0])
            self.r.violation("cut_overlap", f"{name}: {int(bad.sum())} drawn clusters are members of groups that produced "
                                            f"other drawn clusters, e.g. {self.cl(c)} with output {self.cl(x)} of group {g}")
            return False
        return True

    def note_pinched(self, name, U, stats):
        p = self.pinched_edges(U)
        n = int(p.sum())
        # Four, six or more unmarked uses are all pinches (FORMAT.md §6): counted, not warned.
        if n:
            stats["cuts_with_pinched_edges"] += 1
            stats["max_pinched_edges"] = max(stats["max_pinched_edges"], n)
        return n

    def check_cut(self, name, sel, stats=None):
        U, M = self.use_counts(self.cluster_tris_mask(sel))
        bad = self.bad_edges(U, M)
        ok = self.check_overlap(name, sel)
        if bad.any():
            if len(self.r.violations.get("cracked_cut", {"examples": []})["examples"]) < MAX_EXAMPLES:
                self.r.violation("cracked_cut", self.describe_cut_failure(name, sel, U, M, bad))
            else:  # describing costs a scan of every triangle: only the printed examples
                self.r.violations["cracked_cut"]["count"] += 1
            ok = False
        if stats is not None:
            self.note_pinched(name, U, stats)
        return ok

    def uniform_thresholds(self):
        fin = self.gerror[np.isfinite(self.gerror)].astype(np.float64)
        return np.unique(np.concatenate([[0.0], fin]))

    def uniform_sel(self, t):
        return (self.own_err <= t) & (t < self.par_err)

    def check_uniform_cuts(self):
        """Every uniform cut (spec section 6), incrementally: a cluster is drawn
        for thresholds T[i] with enter <= i < leave. cnt holds the cut's uses in
        the 2E numbering of self.euse (unmarked, then marked)."""
        t0 = time.perf_counter()
        T = self.uniform_thresholds()
        self.T = T
        E = self.E
        own = self.own_err.astype(np.float64)
        par = self.par_err.astype(np.float64)
        enter = np.searchsorted(T, own, side="left")
        leave = np.searchsorted(T, par, side="left")
        live = enter < leave
        tc = np.where(self.hdr_ok, self.ctc, 0)
        cnt = np.zeros(2 * E, dtype=np.int64)
        bad = np.zeros(E, dtype=bool)
        nbad = 0
        order_in = np.argsort(enter, kind="stable")
        order_out = np.argsort(leave, kind="stable")
        ein = enter[order_in]
        eout = leave[order_out]
        failures = 0
        stats = {"cuts_with_pinched_edges": 0, "max_pinched_edges": 0}
        pin = np.zeros(E, dtype=bool)
        npin = 0
        for i in range(T.size):
            add = order_in[np.searchsorted(ein, i, "left"):np.searchsorted(ein, i, "right")]
            add = add[live[add]]
            rem = order_out[np.searchsorted(eout, i, "left"):np.searchsorted(eout, i, "right")]
            rem = rem[live[rem]]
            if add.size == 0 and rem.size == 0 and i > 0:
                continue
            ea = self.euse[np.repeat(self.tbase[add], tc[add]) + seg_arange(tc[add])].reshape(-1)
            er = self.euse[np.repeat(self.tbase[rem], tc[rem]) + seg_arange(tc[rem])].reshape(-1)
            touched = np.unique(np.concatenate([ea, er]) % E)
            before = int(bad[touched].sum())
            ua, ca = np.unique(ea, return_counts=True)
            cnt[ua] += ca
            ur, cr = np.unique(er, return_counts=True)
            cnt[ur] -= cr
            ut = cnt[touched]
            nb = self.bad_edges(ut, cnt[touched + E])
            bad[touched] = nb
            nbad += int(nb.sum()) - before
            name = f"uniform cut t={fmt_f(T[i])}"
            sel = self.uniform_sel(T[i])
            ok = self.check_overlap(name, sel)
            if nbad:
                if failures < MAX_EXAMPLES:
                    self.r.violation("cracked_cut", self.describe_cut_failure(name, sel, cnt[:E], cnt[E:], bad))
                else:
                    self.r.violations["cracked_cut"]["count"] += 1
            if nbad or not ok:
                failures += 1
            bp = int(pin[touched].sum())
            np_t = ~self.special[touched] & (ut >= 4)
            pin[touched] = np_t
            npin += int(np_t.sum()) - bp
            if npin:
                stats["cuts_with_pinched_edges"] += 1
                stats["max_pinched_edges"] = max(stats["max_pinched_edges"], npin)
                if (np_t & (ut > 4)).any():
                    self.note_pinched(name, cnt[:E], {"cuts_with_pinched_edges": 0, "max_pinched_edges": 0})
        # sanity: the incremental counts equal a direct count at the last threshold
        direct = np.concatenate(self.use_counts(self.cluster_tris_mask(self.uniform_sel(T[-1]))))
        if not np.array_equal(direct, cnt):
            self.r.violation("checker_self_check", "incremental uniform-cut edge counts disagree with a direct count")
        if (cnt < 0).any():
            self.r.violation("checker_self_check", "negative edge count in the uniform sweep")
        f = self.r.figures
        f["uniform_cuts"] = int(T.size)
        f["uniform_cracked"] = failures
        f["uniform_cuts_with_pinched_edges"] = stats["cuts_with_pinched_edges"]
        f["uniform_max_pinched_edges"] = stats["max_pinched_edges"]
        top = self.uniform_sel(T[-1])
        f["coarsest_cut_triangles"] = int(self.ctc[top].sum())
        self._lap("uniform_cuts", t0)

    def random_cameras(self):
        rng = np.random.default_rng(self.opts.seed)
        l0 = self.vcl.size and self.clevel[self.vcl] == 0
        pts = self.pos[l0] if np.any(l0) else self.pos
        lo, hi = pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64)
        centre = (lo + hi) / 2
        radius = float(self.gradius.max())
        if not radius > 0:
            radius = float(np.linalg.norm(hi - lo) / 2) or 1.0
        cams = []
        for _ in range(self.opts.random_cuts):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d) or 1.0
            eye = centre + d * radius * 10.0 ** rng.uniform(-1.3, 1.2)
            tau = float(TAUS[int(rng.integers(len(TAUS)))])
            cams.append((eye, tau))
        return cams, radius

    def projected(self, eye, z_near, proj11):
        """Section 6: per-group projected error, evaluated in f32."""
        f32 = np.float32
        e = eye.astype(f32)
        with np.errstate(over="ignore", invalid="ignore"):
            return self._projected(e, z_near, proj11)

    def _projected(self, e, z_near, proj11):
        f32 = np.float32
        dx = self.gcenter[:, 0] - e[0]
        dy = self.gcenter[:, 1] - e[1]
        dz = self.gcenter[:, 2] - e[2]
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        d = np.maximum(d - self.gradius, z_near)
        with np.errstate(over="ignore", invalid="ignore"):
            pr = self.gerror / d * f32(VIEW_H * 0.5) * proj11
        return np.where(self.gerror == 0, f32(0), pr).astype(f32)

    def view_sel(self, eye, tau, z_near, proj11):
        pr = self.projected(eye, z_near, proj11)
        own_pr = np.where(self.has_own, pr[np.where(self.has_own, self.cown, 0)], np.float32(0))
        par_pr = pr[self.cgroup]
        tau = np.float32(tau)
        return (own_pr <= tau) & (tau < par_pr), own_pr, par_pr

    def check_random_cuts(self):
        t0 = time.perf_counter()
        cams, radius = self.random_cameras()
        self.cams = cams
        self.cam_radius = radius
        self.z_near = np.float32(radius * 1e-3)
        self.proj11 = np.float32(1.0 / math.tan(math.radians(FOV_Y_DEG) / 2))
        failures = 0
        nonmono = 0
        sizes = []
        stats = {"cuts_with_pinched_edges": 0, "max_pinched_edges": 0}
        for i, (eye, tau) in enumerate(cams):
            sel, own_pr, par_pr = self.view_sel(eye, tau, self.z_near, self.proj11)
            # the f32 eye actually used, exactly (for `mres export --camera`)
            eye_s = ",".join(repr(float(x)) for x in eye.astype(np.float32))
            sizes.append(int(self.ctc[sel].sum()))
            nm = self.has_own & (own_pr > par_pr)
            if nm.any():
                # some threshold between the two values would draw both a cluster's
                # parents and its children: section 6 promises crack-free cuts for any tau
                nonmono += 1
                c = int(np.flatnonzero(nm)[0])
                ulps = int(own_pr[c].view(np.int32)) - int(par_pr[c].view(np.int32))
                # tau = parent value: c is not drawn (own > tau) but its parent group's
                # outputs are (their own value is this parent value <= tau)
                bad_tau = float(par_pr[c])
                sel2 = self.view_sel(eye, bad_tau, self.z_near, self.proj11)[0]
                go, gp = int(self.cown[c]), int(self.cgroup[c])
                n_children = int((sel2 & (self.cgroup == go)).sum())   # members of c's own group
                n_parents = int((sel2 & (self.cown == gp)).sum())      # outputs of c's parent group
                self.r.violation("projected_not_monotone",
                                 f"camera {i} eye {eye_s}: {self.cl(c)} own group {self.cown[c]} "
                                 f"projects to {float(own_pr[c])!r} > parent group {self.cgroup[c]} {float(par_pr[c])!r} "
                                 f"({ulps} ulp, f32 rounding; {int(nm.sum())} clusters): at tau {bad_tau!r} the cut draws "
                                 f"{n_children} members of group {go} and {n_parents} outputs of group {gp}"
                                 f"{' (overlapping levels)' if n_children and n_parents else ''}")
            if not self.check_cut(f"view cut {i} (eye {eye_s}, tau {tau})", sel, stats):
                failures += 1
        f = self.r.figures
        f["random_cuts"] = len(cams)
        f["random_cracked"] = failures
        f["random_cuts_with_pinched_edges"] = stats["cuts_with_pinched_edges"]
        f["random_max_pinched_edges"] = stats["max_pinched_edges"]
        f["random_not_monotone"] = nonmono
        if sizes:
            f["random_cut_triangles"] = {"min": min(sizes), "median": int(np.median(sizes)), "max": max(sizes)}
        self._lap("random_cuts", t0)

    # -- trimesh cross-checks ------------------------------------------------
    def cut_mesh(self, sel):
        import trimesh
        faces_g = self.tw[self.cluster_tris_mask(sel)]
        used, inv = np.unique(faces_g.reshape(-1), return_inverse=True)
        mesh = trimesh.Trimesh(vertices=self.wgrid[used], faces=inv.reshape(-1, 3), process=False, validate=False)
        return mesh, used

    def boundary_keys_trimesh(self, mesh, used):
        """Keys of the edges trimesh finds used an odd number of times (the
        boundary: open edges, and non-manifold edges with an odd count)."""
        import trimesh
        es = mesh.edges_sorted
        first, inverse = trimesh.grouping.unique_rows(es)
        odd = (np.bincount(inverse.reshape(-1), minlength=len(first)) & 1) == 1
        g = used[es[first[odd]]]
        lo = np.minimum(g[:, 0], g[:, 1])
        hi = np.maximum(g[:, 0], g[:, 1])
        return np.unique(lo * self.NW + hi)

    def compare_boundary(self, name, bk, U, M):
        """trimesh's boundary of a cut must be its marked edges (rule (c) makes
        every odd edge a marked one), and the checker's own odd edges."""
        marked = self.ekeys[M > 0]
        if not np.array_equal(bk, marked):
            unmarked = np.setdiff1d(bk, marked)
            inner = np.setdiff1d(marked, bk)
            ex = unmarked[0] if unmarked.size else inner[0]
            a, b = divmod(int(ex), self.NW)
            self.r.violation("trimesh_boundary",
                             f"{name}: boundary edges differ from the marked edges ({unmarked.size} boundary edges "
                             f"unmarked, {inner.size} marked edges not on the boundary), e.g. edge "
                             f"{self.wq[a].tolist()}-{self.wq[b].tolist()}")
        if not np.array_equal(bk, self.ekeys[((U + M) & 1) == 1]):
            self.r.violation("checker_self_check", f"{name}: trimesh and edge counting disagree on boundary edges")

    def topology_of(self, mesh):
        import trimesh  # noqa: F401
        return {"watertight": bool(mesh.is_watertight), "euler": int(mesh.euler_number),
                "bodies": int(mesh.body_count), "winding_consistent": bool(mesh.is_winding_consistent)}

    @staticmethod
    def pinch_stats(mesh):
        """Non-manifold ("pinch") vertices: vertices whose incident triangles form
        more than one edge-connected fan; and the Euler characteristic after
        splitting them (what a manifold surface with the same faces would have)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        faces = np.asarray(mesh.faces, dtype=np.int64)
        nv = int(faces.max()) + 1 if faces.size else 0
        v = faces.reshape(-1)
        b = faces[:, [1, 2, 0]].reshape(-1)
        c = faces[:, [2, 0, 1]].reshape(-1)
        keys = np.concatenate([v * nv + b, v * nv + c])
        uk, inv = np.unique(keys, return_inverse=True)
        n = v.size
        g = coo_matrix((np.ones(n, dtype=np.int8), (inv[:n], inv[n:])), shape=(uk.size, uk.size))
        ncomp, labels = connected_components(g, directed=False)
        fan_keys = np.unique((uk // nv) * ncomp + labels)
        fans = np.bincount(fan_keys // ncomp, minlength=nv)
        extra = int((fans[fans > 1] - 1).sum())
        # edge-connected components of faces (faces sharing an edge)
        fe = np.sort(np.stack([faces, faces[:, [1, 2, 0]]], axis=2).reshape(-1, 2), axis=1)
        ek, einv = np.unique(fe[:, 0] * nv + fe[:, 1], return_inverse=True)
        fidx = np.repeat(np.arange(len(faces)), 3)
        # bipartite graph faces <-> edges
        m = len(faces)
        g2 = coo_matrix((np.ones(fidx.size, dtype=np.int8), (fidx, m + einv)), shape=(m + ek.size, m + ek.size))
        fcomp = connected_components(g2, directed=False)[0]
        return {"pinch_vertices": int((fans > 1).sum()), "euler_split": int(mesh.euler_number) + extra,
                "face_components": int(fcomp)}

    def trimesh_checks(self):
        t0 = time.perf_counter()
        r = self.r
        level0 = self.clevel == 0
        mesh0, used0 = self.cut_mesh(level0 & self.hdr_ok)
        self.mesh0 = mesh0
        src = self.topology_of(mesh0)
        self.compare_boundary("level 0", self.boundary_keys_trimesh(mesh0, used0), self.U0, self.M0)
        src0 = self.pinch_stats(mesh0)
        src.update(src0)
        r.figures["level0_topology"] = src
        # which cuts: every uniform cut up to --trimesh-uniform, else evenly spaced
        T = self.T
        k = self.opts.trimesh_uniform
        if k <= 0 or T.size <= k:
            uni = list(range(T.size))
        else:
            uni = sorted(set(np.linspace(0, T.size - 1, k).round().astype(int).tolist()))
        cuts = [(f"uniform cut t={fmt_f(T[i])}", self.uniform_sel(T[i])) for i in uni]
        nr = min(self.opts.trimesh_random, len(self.cams))
        for i in range(nr):
            eye, tau = self.cams[i]
            cuts.append((f"view cut {i}", self.view_sel(eye, tau, self.z_near, self.proj11)[0]))
        euler_info = 0
        rows = []
        for name, sel in cuts:
            if not sel.any():
                r.violation("empty_cut", f"{name}: selects no cluster")
                continue
            mesh, used = self.cut_mesh(sel)
            top = self.topology_of(mesh)
            U, M = self.use_counts(self.cluster_tris_mask(sel))
            self.compare_boundary(name, self.boundary_keys_trimesh(mesh, used), U, M)
            # watertight = every used edge used exactly twice: marked (open) edges and
            # pinched edges (used 4 times, allowed by section 6) make it false
            total = U + M
            expect_wt = bool(((total == 0) | (total == 2)).all())
            if top["watertight"] != expect_wt:
                r.violation("trimesh_watertight", f"{name}: is_watertight {top['watertight']}, expected {expect_wt} "
                                                  f"({int((M > 0).sum())} marked edges, "
                                                  f"{int(self.pinched_edges(U).sum())} pinched edges)")
            if top["bodies"] == src["bodies"]:
                if top["euler"] != src["euler"]:
                    msg = (f"{name}: Euler characteristic {top['euler']} != level 0 {src['euler']} with the same "
                           f"{top['bodies']} components")
                    table = r.violations if self.opts.strict_topology else r.warnings
                    kind = "trimesh_euler" if self.opts.strict_topology else "euler_changed"
                    if len(table.get(kind, {"examples": []})["examples"]) < MAX_EXAMPLES:
                        # explain the first few (costly on big cuts)
                        ex = self.pinch_stats(mesh)
                        msg += (f" ({ex['pinch_vertices']} non-manifold (pinch) vertices, "
                                f"Euler {ex['euler_split']} after splitting them, {ex['face_components']} edge-connected "
                                f"components; level 0: {src0['pinch_vertices']} pinch vertices, "
                                f"{src0['face_components']} edge-connected components)")
                    if self.opts.strict_topology:
                        r.violation("trimesh_euler", msg)
                    else:
                        r.warn("euler_changed", msg)
            else:
                euler_info += 1
                r.note("components_changed", f"{name}: {top['bodies']} components (level 0: {src['bodies']}), "
                                             f"Euler {top['euler']} (level 0: {src['euler']})")
            if top["winding_consistent"] != src["winding_consistent"]:
                r.note("winding_changed", f"{name}: winding consistent {top['winding_consistent']}, level 0 "
                                          f"{src['winding_consistent']}")
            rows.append(top)
        r.figures["trimesh_cuts"] = len(cuts)
        self._lap("trimesh", t0)

    # -- distances -----------------------------------------------------------
    def distances(self):
        import trimesh
        t0 = time.perf_counter()
        n = self.opts.distance_samples
        if n <= 0:
            return
        errs = np.unique(self.gerror[np.isfinite(self.gerror) & (self.gerror > 0)].astype(np.float64))
        out = []
        if errs.size:
            q0 = trimesh.proximity.ProximityQuery(self.mesh0)
            pts0 = trimesh.sample.sample_surface(self.mesh0, n, seed=self.opts.seed)[0]
            for frac in (0.25, 0.5, 0.75):
                t = float(errs[int(round(frac * (errs.size - 1)))])
                mesh, _ = self.cut_mesh(self.uniform_sel(t))
                pts = trimesh.sample.sample_surface(mesh, n, seed=self.opts.seed + 1)[0]
                step = float(self.step)
                d_cut = q0.on_surface(pts)[1] * step                     # cut -> level 0
                d_l0 = trimesh.proximity.ProximityQuery(mesh).on_surface(pts0)[1] * step  # level 0 -> cut
                out.append({
                    "fraction": frac, "t": t, "cut_triangles": int(len(mesh.faces)),
                    "cut_to_level0": {"max": float(d_cut.max()), "mean": float(d_cut.mean()),
                                      "max_ratio": float(d_cut.max() / t), "mean_ratio": float(d_cut.mean() / t)},
                    "level0_to_cut": {"max": float(d_l0.max()), "mean": float(d_l0.mean()),
                                      "max_ratio": float(d_l0.max() / t), "mean_ratio": float(d_l0.mean() / t)},
                })
        self.r.figures["distances"] = out
        if self.opts.source:
            self.source_distance(trimesh)
        self._lap("distances", t0)

    def source_distance(self, trimesh):
        n = self.opts.distance_samples
        try:
            src = trimesh.load(self.opts.source, force="mesh", process=False)
        except Exception as exc:  # noqa: BLE001 - any loader failure is reported
            self.r.note("source_load", f"cannot load {self.opts.source}: {exc}")
            return
        step = float(self.step)
        # into grid units, like the level-0 mesh (see build_topology)
        verts = (np.asarray(src.vertices, dtype=np.float64) - self.origin.astype(np.float64)) / step - self.qcentre
        src = trimesh.Trimesh(vertices=verts, faces=src.faces, process=False, validate=False)
        pts_src = trimesh.sample.sample_surface(src, n, seed=self.opts.seed + 2)[0]
        pts_l0 = trimesh.sample.sample_surface(self.mesh0, n, seed=self.opts.seed + 3)[0]
        d1 = trimesh.proximity.ProximityQuery(src).on_surface(pts_l0)[1] * step
        d2 = trimesh.proximity.ProximityQuery(self.mesh0).on_surface(pts_src)[1] * step
        self.r.figures["source_distance"] = {
            "source": self.opts.source, "source_triangles": int(len(src.faces)), "grid_step": step,
            "level0_to_source": {"max": float(d1.max()), "mean": float(d1.mean()), "max_steps": float(d1.max() / step)},
            "source_to_level0": {"max": float(d2.max()), "mean": float(d2.mean()), "max_steps": float(d2.max() / step)},
        }

    # -- driver ----------------------------------------------------------------
    def run(self):
        t = time.perf_counter()
        self.read_header()
        self.read_tables()
        self.check_groups()
        self.check_clusters()
        self.check_pages()
        self.check_dependencies()
        self.invariants_done = False
        self.check_invariants()
        self._lap("tables", t)
        self.decode_pages()
        self.check_cluster_headers()
        self.decode_clusters()
        f = self.r.figures
        f["bytes"] = len(self.data)
        f["pages"] = self.P
        f["groups"] = self.G
        f["clusters"] = self.C
        f["flags"] = [n for b, n in ((FLAG_NORMALS, "normals"), (FLAG_UVS, "uvs"), (FLAG_MATERIALS, "materials"),
                                     (FLAG_LAYOUT_PAGES, "layout_pages")) if self.flags & b]
        f["grid_step"] = float(self.step)
        f["source_triangles"] = int(self.source_triangles)
        if not (self.complete and self.invariants_done):
            self.r.note("cuts_skipped", "cut, trimesh and distance checks skipped: not every cluster decoded cleanly")
            return
        self.build_topology()
        self.check_marks()
        self.check_uniform_cuts()
        self.check_random_cuts()
        if not self.opts.no_trimesh:
            self.trimesh_checks()
            self.distances()


def check_path(path, opts):
    report = Report(path)
    t = time.perf_counter()
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        report.io_error = str(exc)
        return report
    checker = Checker(path, memoryview(data), opts, report)
    try:
        checker.run()
    except Fatal:
        pass
    except Exception as exc:  # noqa: BLE001 - never a traceback on a bad file
        report.violation("checker_error", f"unexpected {type(exc).__name__} while checking: {exc} "
                                          "(the file is malformed in a way not anticipated, or this is a checker bug)")
        if opts.debug:
            raise
    report.figures["timings"] = checker.timings
    report.figures["seconds"] = round(time.perf_counter() - t, 3)
    return report


def print_report(rep, out):
    f = rep.figures
    if rep.io_error:
        print(f"{rep.path}: ERROR cannot read: {rep.io_error}", file=out)
        return
    status = "PASS" if rep.ok else f"FAIL ({rep.violation_count} violations of {len(rep.violations)} kinds)"
    head = [f"{rep.path}: {status}"]
    for k in ("levels", "groups", "clusters", "pages", "root_groups"):
        if k in f:
            head.append(f"{k}={f[k]}")
    if "level0_fill" in f:
        head.append(f"level0_fill={f['level0_fill']:.2f}")
    if "level0_marked_edges" in f:
        head.append(f"level0_marked_edges={f['level0_marked_edges']}")
    for k in ("uniform_cuts", "random_cuts", "trimesh_cuts"):
        if k in f:
            head.append(f"{k}={f[k]}")
    head.append(f"({f.get('seconds', 0):.2f} s)")
    print(" ".join(head), file=out)
    if "per_level" in f:
        print("  per level: " + "; ".join(f"L{x['level']} {x['clusters']}c/{x['groups']}g/{x['triangles']}t"
                                          for x in f["per_level"]), file=out)
    if f.get("uniform_cuts_with_pinched_edges") or f.get("random_cuts_with_pinched_edges"):
        print(f"  pinched edges (used 4 times, allowed): in {f.get('uniform_cuts_with_pinched_edges', 0)} uniform cuts "
              f"(max {f.get('uniform_max_pinched_edges', 0)}) and {f.get('random_cuts_with_pinched_edges', 0)} "
              f"random cuts (max {f.get('random_max_pinched_edges', 0)})", file=out)
    for kind, v in sorted(rep.violations.items()):
        print(f"  VIOLATION [{kind}] x{v['count']}", file=out)
        for e in v["examples"]:
            print(f"    - {e}", file=out)
    for kind, v in sorted(rep.warnings.items()):
        print(f"  WARNING [{kind}] x{v['count']}", file=out)
        for e in v["examples"]:
            print(f"    - {e}", file=out)
    for kind, v in sorted(rep.notes.items()):
        print(f"  note [{kind}] x{v['count']}: {v['examples'][0] if v['examples'] else ''}", file=out)
    for d in f.get("distances", []):
        print(f"  distance at t={d['t']:.4g} ({d['cut_triangles']} tris): cut->L0 max {d['cut_to_level0']['max_ratio']:.3f}t "
              f"mean {d['cut_to_level0']['mean_ratio']:.3f}t; L0->cut max {d['level0_to_cut']['max_ratio']:.3f}t "
              f"mean {d['level0_to_cut']['mean_ratio']:.3f}t", file=out)
    if "source_distance" in f:
        s = f["source_distance"]
        print(f"  source distance (grid_step {s['grid_step']:.4g}): L0->source max {s['level0_to_source']['max']:.4g} "
              f"({s['level0_to_source']['max_steps']:.2f} steps) mean {s['level0_to_source']['mean']:.4g}; "
              f"source->L0 max {s['source_to_level0']['max']:.4g} ({s['source_to_level0']['max_steps']:.2f} steps) "
              f"mean {s['source_to_level0']['mean']:.4g}", file=out)


def to_json(rep):
    obj = {"file": rep.path, "ok": rep.ok}
    if rep.io_error:
        obj["io_error"] = rep.io_error
    obj.update(rep.figures)
    obj["violation_count"] = rep.violation_count
    obj["violations"] = [{"kind": k, **v} for k, v in sorted(rep.violations.items())]
    obj["warnings"] = [{"kind": k, **v} for k, v in sorted(rep.warnings.items())]
    obj["notes"] = [{"kind": k, **v} for k, v in sorted(rep.notes.items())]
    return obj


def main(argv=None):
    ap = argparse.ArgumentParser(description="Independent checker for .mres files (docs/FORMAT.md).")
    ap.add_argument("files", nargs="+", metavar="FILE.mres")
    ap.add_argument("--source", help="original mesh (OBJ/glTF) to measure the level-0 surface against")
    ap.add_argument("--random-cuts", type=int, default=200, help="random view-dependent cuts (default 200)")
    ap.add_argument("--seed", type=int, default=1, help="seed of cameras and surface samples (default 1)")
    ap.add_argument("--json", action="store_true", help="print one JSON object per file (JSON Lines)")
    ap.add_argument("--distance-samples", type=int, default=2000,
                    help="surface samples per side for distance measurements (default 2000; 0 disables)")
    ap.add_argument("--trimesh-uniform", type=int, default=24,
                    help="uniform cuts cross-checked with trimesh: all if there are at most this many, "
                         "else this many evenly spaced (0 = all; default 24)")
    ap.add_argument("--trimesh-random", type=int, default=20,
                    help="random view cuts cross-checked with trimesh (default 20)")
    ap.add_argument("--strict-topology", action="store_true",
                    help="a cut whose Euler characteristic differs from level 0 with the same number of components is "
                         "a violation (default: a warning; the spec only promises edge multiplicities)")
    ap.add_argument("--no-trimesh", action="store_true", help="skip trimesh cross-checks and distances")
    ap.add_argument("--debug", action="store_true", help="re-raise unexpected exceptions")
    opts = ap.parse_args(argv)
    if opts.random_cuts < 0 or opts.distance_samples < 0:
        ap.error("counts must be >= 0")
    if opts.source and len(opts.files) != 1:
        ap.error("--source needs exactly one FILE")
    status = 0
    for path in opts.files:
        rep = check_path(path, opts)
        if opts.json:
            print(json.dumps(to_json(rep)), flush=True)
        else:
            print_report(rep, sys.stdout)
            sys.stdout.flush()
        if rep.io_error:
            status = 2
        elif not rep.ok and status == 0:
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
