/*
 * load.c: streams a .mres file the way an engine would, through the C ABI only.
 *
 *   load FILE.mres
 *
 * Reads the fixed header, then only the resident prefix (mres_prefix_len), opens the index,
 * then for every page reads its byte range with fseek/fread and decodes it. Checks each
 * cluster's decoded arrays against its record (counts, index range, the grid formula of the
 * float positions) and prints a summary, one "key value" per line:
 *
 *   pages, clusters, triangles, vertices, gpu_bytes, dependencies, level0_clusters,
 *   root_clusters, read_bytes, hash (FNV-1a 64 over every cluster's positions, indices,
 *   materials, open-edge marks, normals and UVs as little-endian bytes, in cluster order)
 *
 * On a failed call prints "error: STATUS_NAME: message" to stderr and exits 1; on a failed
 * check, "check failed: ..." and exits 2. tests/c_program.rs builds and runs it.
 */
#include "mres.h"

#include <float.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHECK_CALL(call)                                                                      \
    do {                                                                                      \
        MresStatus status_ = (call);                                                          \
        if (status_ != MRES_OK) {                                                             \
            fprintf(stderr, "error: %s: %s\n", mres_status_name(status_),                     \
                    mres_last_error_message());                                               \
            exit(1);                                                                          \
        }                                                                                     \
    } while (0)

#define EXPECT(cond, ...)                                                                     \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "check failed: " __VA_ARGS__);                                    \
            fprintf(stderr, "\n");                                                            \
            exit(2);                                                                          \
        }                                                                                     \
    } while (0)

static uint64_t hash = 14695981039346656037ull; /* FNV-1a 64 offset basis */
static uint64_t read_bytes = 0;

static void hash_byte(uint8_t b) {
    hash ^= b;
    hash *= 1099511628211ull;
}

static void hash_u32(uint32_t v) {
    for (int k = 0; k < 4; k++) hash_byte((uint8_t)(v >> (8 * k)));
}

static void hash_f32(float f) {
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    hash_u32(bits);
}

/* Reads `len` bytes at `offset` of `file` into a new buffer; reads fewer at the end of the
 * file and stores how many in *got (the library then reports the shortfall). */
static uint8_t *fetch(FILE *file, uint64_t offset, size_t len, size_t *got) {
    uint8_t *buf = malloc(len ? len : 1);
    EXPECT(buf != NULL, "out of memory for %zu bytes", len);
    EXPECT(fseek(file, (long)offset, SEEK_SET) == 0, "seek to %llu", (unsigned long long)offset);
    *got = fread(buf, 1, len, file);
    read_bytes += *got;
    return buf;
}

static MresIndex *open_index(FILE *file) {
    size_t got;
    uint8_t *head = fetch(file, 0, mres_header_size(), &got);
    uint64_t prefix_len = 0;
    CHECK_CALL(mres_prefix_len(head, got, &prefix_len));
    free(head);
    uint8_t *prefix = fetch(file, 0, (size_t)prefix_len, &got);
    MresIndex *index = NULL;
    CHECK_CALL(mres_index_open(prefix, got, &index));
    free(prefix); /* the index keeps no pointer into it */
    return index;
}

/* Per-cluster arrays, checked against the cluster's record; returns its triangle count. */
static uint32_t check_cluster(const MresIndex *index, const MresInfo *info, const MresPage *page,
                              uint32_t c) {
    MresCluster rec;
    CHECK_CALL(mres_index_cluster(index, c, &rec));
    int32_t q[3 * 256];
    float p[3 * 256], normals[3 * 256], uvs[2 * 256];
    uint8_t indices[3 * 128], edges[128];
    uint16_t materials[128];
    size_t nq, np, nn, nu, ni, ne, nm;
    CHECK_CALL(mres_page_cluster_positions(page, c, q, 3 * 256, &nq));
    CHECK_CALL(mres_page_cluster_positions_f32(page, c, p, 3 * 256, &np));
    CHECK_CALL(mres_page_cluster_normals(page, c, normals, 3 * 256, &nn));
    CHECK_CALL(mres_page_cluster_uvs(page, c, uvs, 2 * 256, &nu));
    CHECK_CALL(mres_page_cluster_indices(page, c, indices, 3 * 128, &ni));
    CHECK_CALL(mres_page_cluster_open_edges(page, c, edges, 128, &ne));
    CHECK_CALL(mres_page_cluster_materials(page, c, materials, 128, &nm));

    size_t v = rec.vertex_count, t = rec.triangle_count;
    EXPECT(nq == 3 * v && np == 3 * v, "cluster %u: %zu positions for %zu vertices", c, nq, v);
    EXPECT(ni == 3 * t && ne == t, "cluster %u: %zu indices for %zu triangles", c, ni, t);
    EXPECT(nn == (info->flags & MRES_FLAG_NORMALS ? 3 * v : 0), "cluster %u: %zu normals", c, nn);
    EXPECT(nu == (info->flags & MRES_FLAG_UVS ? 2 * v : 0), "cluster %u: %zu uvs", c, nu);
    EXPECT(nm == (info->flags & MRES_FLAG_MATERIALS ? t : 0), "cluster %u: %zu materials", c, nm);
    for (size_t i = 0; i < ni; i++)
        EXPECT(indices[i] < v, "cluster %u: index %u >= %zu vertices", c, indices[i], v);
    /* The spec's f32 formula, evaluated here (compiled with -ffp-contract=off): same bits. */
    for (size_t i = 0; i < nq; i++) {
        float expected = info->grid_origin[i % 3] + (float)q[i] * info->grid_step;
        EXPECT(memcmp(&expected, &p[i], sizeof expected) == 0, "cluster %u: position %zu", c, i);
    }

    for (size_t i = 0; i < nq; i++) hash_u32((uint32_t)q[i]);
    for (size_t i = 0; i < ni; i++) hash_byte(indices[i]);
    for (size_t i = 0; i < nm; i++) {
        hash_byte((uint8_t)materials[i]);
        hash_byte((uint8_t)(materials[i] >> 8));
    }
    for (size_t i = 0; i < ne; i++) hash_byte(edges[i]);
    for (size_t i = 0; i < nn; i++) hash_f32(normals[i]);
    for (size_t i = 0; i < nu; i++) hash_f32(uvs[i]);
    return (uint32_t)t;
}

/* The streaming path: mres_page_layout gives page `p`'s layout `gpu` (what mres_page_bytes
   gave) from the same fetched bytes and its sources' layouts, without decoding clusters; a
   size query first, and a buffer one byte short is refused. */
static void check_layout(const MresIndex *index, uint32_t p, const uint8_t *bytes, size_t len,
                         const MresPage **sources, size_t source_count, const uint8_t *gpu,
                         size_t gpu_len) {
    const uint8_t **layouts = malloc(sizeof *layouts * (source_count ? source_count : 1));
    size_t *lens = malloc(sizeof *lens * (source_count ? source_count : 1));
    EXPECT(layouts != NULL && lens != NULL, "out of memory");
    for (size_t i = 0; i < source_count; i++) CHECK_CALL(mres_page_bytes(sources[i], &layouts[i], &lens[i]));
    size_t need = 0;
    CHECK_CALL(mres_page_layout(index, p, bytes, len, layouts, lens, source_count, NULL, 0, &need));
    EXPECT(need == gpu_len, "page %u: layout size %zu, decoded %zu", p, need, gpu_len);
    uint8_t *out = malloc(need ? need : 1);
    EXPECT(out != NULL, "out of memory");
    if (need > 0) {
        MresStatus short_buffer = mres_page_layout(index, p, bytes, len, layouts, lens, source_count, out, need - 1, &need);
        EXPECT(short_buffer == MRES_ERR_BUFFER_TOO_SMALL, "page %u: a short buffer gave %s", p, mres_status_name(short_buffer));
    }
    CHECK_CALL(mres_page_layout(index, p, bytes, len, layouts, lens, source_count, out, need, &need));
    EXPECT(need == gpu_len && memcmp(out, gpu, gpu_len) == 0, "page %u: mres_page_layout differs from mres_page_bytes", p);
    free(out);
    free(lens);
    free(layouts);
}

/* Fetches, decodes and checks page `p`, given `pages`, the pages decoded before it (its
   sources are among them: they come before it in the file); adds its figures to the totals
   and returns it. */
static MresPage *load_page(FILE *file, const MresIndex *index, const MresInfo *info, uint32_t p,
                           MresPage *const *pages, uint64_t *triangles, uint64_t *gpu_bytes,
                           uint64_t *sources) {
    MresPageInfo entry;
    CHECK_CALL(mres_index_page(index, p, &entry));
    uint64_t offset, size;
    CHECK_CALL(mres_page_range(index, p, &offset, &size));
    EXPECT(offset == entry.offset && size == entry.compressed_size, "page %u: range", p);
    size_t got;
    uint8_t *bytes = fetch(file, offset, (size_t)size, &got);
    size_t source_count;
    CHECK_CALL(mres_page_sources(index, p, NULL, 0, &source_count));
    uint32_t *source_pages = malloc(sizeof *source_pages * (source_count ? source_count : 1));
    const MresPage **source_handles = malloc(sizeof *source_handles * (source_count ? source_count : 1));
    EXPECT(source_pages != NULL && source_handles != NULL, "out of memory");
    CHECK_CALL(mres_page_sources(index, p, source_pages, source_count, &source_count));
    for (size_t i = 0; i < source_count; i++) {
        EXPECT(source_pages[i] < p, "page %u: source %u is not before it", p, source_pages[i]);
        source_handles[i] = pages[source_pages[i]];
    }
    *sources += source_count;
    MresPage *page = NULL;
    CHECK_CALL(mres_page_decode(index, p, bytes, got, source_handles, source_count, &page));

    const uint8_t *gpu;
    size_t gpu_len;
    CHECK_CALL(mres_page_bytes(page, &gpu, &gpu_len));
    EXPECT(gpu != NULL && gpu_len == entry.raw_size, "page %u: %zu GPU bytes", p, gpu_len);
    check_layout(index, p, bytes, got, source_handles, source_count, gpu, gpu_len);
    free(source_handles);
    free(source_pages);
    free(bytes);
    *gpu_bytes += gpu_len;
    uint32_t first, count;
    CHECK_CALL(mres_page_clusters(page, &first, &count));
    EXPECT(first == entry.first_cluster && count == entry.cluster_count, "page %u: clusters", p);
    for (uint32_t c = first; c < first + count; c++) {
        MresCluster rec;
        CHECK_CALL(mres_index_cluster(index, c, &rec));
        EXPECT(rec.page == p, "cluster %u: record says page %u, found in page %u", c, rec.page, p);
        *triangles += check_cluster(index, info, page, c);
    }
    return page;
}

/* Sizes of the uniform cuts at error 0 (the original clusters) and at FLT_MAX (the root). */
static void print_cuts(const MresIndex *index, const MresInfo *info) {
    uint32_t *cut = malloc(sizeof *cut * (info->cluster_count ? info->cluster_count : 1));
    EXPECT(cut != NULL, "out of memory");
    size_t level0, root;
    CHECK_CALL(mres_select_uniform(index, 0.0f, cut, info->cluster_count, &level0));
    CHECK_CALL(mres_select_uniform(index, FLT_MAX, NULL, 0, &root));
    free(cut);
    printf("level0_clusters %zu\nroot_clusters %zu\n", level0, root);
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: %s FILE.mres\n", argv[0]);
        return 64;
    }
    FILE *file = fopen(argv[1], "rb");
    EXPECT(file != NULL, "cannot open %s", argv[1]);
    MresIndex *index = open_index(file);
    MresInfo info;
    CHECK_CALL(mres_index_info(index, &info));

    uint64_t triangles = 0, gpu_bytes = 0, dependencies = 0, sources = 0;
    /* Every page stays decoded until the end: a later page may copy vertices of it. */
    MresPage **pages = malloc(sizeof *pages * (info.page_count ? info.page_count : 1));
    EXPECT(pages != NULL, "out of memory");
    for (uint32_t p = 0; p < info.page_count; p++) {
        size_t deps;
        CHECK_CALL(mres_page_dependencies(index, p, NULL, 0, &deps));
        dependencies += deps;
        pages[p] = load_page(file, index, &info, p, pages, &triangles, &gpu_bytes, &sources);
    }
    for (uint32_t p = 0; p < info.page_count; p++) mres_page_free(pages[p]);
    free(pages);
    uint64_t vertices = 0;
    for (uint32_t c = 0; c < info.cluster_count; c++) {
        MresCluster rec;
        CHECK_CALL(mres_index_cluster(index, c, &rec));
        vertices += rec.vertex_count;
    }
    printf("pages %u\nclusters %u\ntriangles %llu\nvertices %llu\ngpu_bytes %llu\n",
           info.page_count, info.cluster_count, (unsigned long long)triangles,
           (unsigned long long)vertices, (unsigned long long)gpu_bytes);
    printf("dependencies %llu\n", (unsigned long long)dependencies);
    printf("sources %llu\n", (unsigned long long)sources);
    print_cuts(index, &info);
    printf("read_bytes %llu\nhash %016llx\n", (unsigned long long)read_bytes,
           (unsigned long long)hash);
    mres_index_free(index);
    fclose(file);
    return 0;
}
