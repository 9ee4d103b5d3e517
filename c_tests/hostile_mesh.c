/* hostile_mesh.c: meshes a renderer might hand over by mistake or malice. Non-finite vertices, bad
 * indices, bad strides, counts that overflow and missing arrays are refused with a specific status
 * and *out untouched; odd strides, misaligned arrays, empty and degenerate meshes are accepted and
 * behave; memory limits are honoured. */
#include "common.h"

#include <stddef.h>

/* Builds `d` with default options; returns the status and leaves *out as the library left it. */
static rq_status build(const rq_mesh_desc *d, rq_scene **out) { return rq_scene_build(d, NULL, NULL, out); }

/* Expects `d` to be refused with `expected` and *out to stay untouched. */
#define CHECK_REFUSED(d, expected, what)                                                             \
  do {                                                                                               \
    rq_scene *out_ = (rq_scene *)test_sentinel();                                                    \
    rq_status s_ = build((d), &out_);                                                                \
    CHECKF(s_ == (expected), "%s: got %u (%s), expected %u (%s)", (what), (unsigned)s_,              \
           rq_status_str(s_), (unsigned)(expected), rq_status_str(expected));                        \
    CHECKF(out_ == (rq_scene *)test_sentinel(), "%s: *out was written", (what));                     \
    if (s_ == RQ_STATUS_OK && out_ != (rq_scene *)test_sentinel()) {                                 \
      rq_scene_free(out_);                                                                           \
    }                                                                                                \
  } while (0)

/* A small test mesh: a unit square at z = 0 (two triangles) plus one triangle at z = 1. */
static const float base_v[7 * 3] = {
    0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 1.0f, 0.0f, 0.0f, 1.0f, 0.0f,
    0.0f, 0.0f, 1.0f, 1.0f, 0.0f, 1.0f, 0.0f, 1.0f, 1.0f,
};
static const uint32_t base_i[3 * 3] = {0, 1, 2, 0, 2, 3, 4, 5, 6};

static rq_mesh_desc base_desc(void) {
  rq_mesh_desc d;
  d.vertices = base_v;
  d.vertex_count = 7;
  d.vertex_stride = 12;
  d.indices = base_i;
  d.triangle_count = 3;
  return d;
}

static void test_non_finite_vertices(void) {
  const float bad[] = {NAN, INFINITY, -INFINITY, -NAN};
  const char *names[] = {"NaN", "+Inf", "-Inf", "-NaN"};
  float v[7 * 3];
  for (size_t b = 0; b < sizeof bad / sizeof bad[0]; b++) {
    /* Every coordinate of every vertex, used by a triangle or not (vertex 3 is used only by the
     * square, all are used; an extra unused vertex is checked below). */
    for (int k = 0; k < 7 * 3; k++) {
      memcpy(v, base_v, sizeof v);
      v[k] = bad[b];
      rq_mesh_desc d = base_desc();
      d.vertices = v;
      char what[64];
      snprintf(what, sizeof what, "%s at coordinate %d", names[b], k);
      CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, what);
    }
  }
  /* A non-finite vertex that no triangle uses is still refused (every coordinate must be finite). */
  float extra[8 * 3];
  memcpy(extra, base_v, sizeof base_v);
  extra[21] = 0.0f;
  extra[22] = NAN;
  extra[23] = 0.0f;
  rq_mesh_desc d = base_desc();
  d.vertices = extra;
  d.vertex_count = 8;
  CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, "NaN in an unused vertex");
  /* Huge but finite coordinates are fine. */
  float big[7 * 3];
  for (int k = 0; k < 7 * 3; k++) {
    big[k] = base_v[k] * 1e30f - 5e29f;
  }
  d = base_desc();
  d.vertices = big;
  rq_scene *scene = NULL;
  CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
  rq_scene_free(scene);
}

static void test_indices(void) {
  const uint32_t bad_values[] = {7, 8, 1000, 0x7FFFFFFFu, 0xFFFFFFFEu, 0xFFFFFFFFu};
  uint32_t idx[9];
  for (size_t b = 0; b < sizeof bad_values / sizeof bad_values[0]; b++) {
    for (int k = 0; k < 9; k++) {
      memcpy(idx, base_i, sizeof idx);
      idx[k] = bad_values[b];
      rq_mesh_desc d = base_desc();
      d.indices = idx;
      char what[64];
      snprintf(what, sizeof what, "index %u at position %d", (unsigned)bad_values[b], k);
      CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, what);
    }
  }
  /* Out of range in a triangle that would be degenerate anyway: still refused. */
  const uint32_t degenerate_bad[6] = {0, 1, 2, 3, 3, 9};
  rq_mesh_desc d = base_desc();
  d.indices = degenerate_bad;
  d.triangle_count = 2;
  CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, "out-of-range index in a degenerate triangle");
  /* Triangles but no vertices at all. */
  d = base_desc();
  d.vertex_count = 0;
  CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, "indices into an empty vertex array");
}

/* Traces a fixed ray set through `scene` into `hits` (RAY_COUNT entries). */
#define RAY_COUNT 400
static void trace_set(const rq_scene *scene, rq_hit *hits) {
  uint64_t rng = 99;
  rq_ray rays[RAY_COUNT];
  for (int i = 0; i < RAY_COUNT; i++) {
    rays[i] = make_ray(rng_float(&rng, -0.2f, 1.2f), rng_float(&rng, -0.2f, 1.2f), 2.0f, 0.0f, 0.0f, -1.0f);
    if (i % 2) {
      rng_dir(&rng, rays[i].dir);
      rays[i].org[2] = 0.5f;
    }
  }
  CHECK_STATUS(rq_scene_intersect_n(scene, rays, hits, RAY_COUNT), RQ_STATUS_OK);
}

static void test_strides(void) {
  /* Strides below 12 bytes cannot hold xyz. */
  const size_t bad[] = {0, 1, 4, 8, 11};
  for (size_t b = 0; b < sizeof bad / sizeof bad[0]; b++) {
    rq_mesh_desc d = base_desc();
    d.vertex_stride = bad[b];
    char what[64];
    snprintf(what, sizeof what, "stride %u", (unsigned)bad[b]);
    CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, what);
  }

  /* Reference hits with stride 12. */
  rq_hit ref[RAY_COUNT], got[RAY_COUNT];
  rq_scene *scene = NULL;
  rq_mesh_desc d = base_desc();
  CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
  if (!scene) {
    return;
  }
  trace_set(scene, ref);
  rq_scene_free(scene);
  int hits = 0;
  for (int i = 0; i < RAY_COUNT; i++) {
    hits += ref[i].prim != RQ_INVALID_ID;
  }
  CHECKF(hits > RAY_COUNT / 4, "only %d of %d reference rays hit", hits, RAY_COUNT);

  /* Strides 12..40 and the vertex array at every byte offset 0..3: the same hits, bit for bit. The
   * padding after xyz is filled with NaN bytes, which must never be read as a coordinate. */
  const size_t strides[] = {12, 13, 15, 16, 17, 24, 40};
  for (size_t s = 0; s < sizeof strides / sizeof strides[0]; s++) {
    for (size_t offset = 0; offset < 4; offset++) {
      size_t stride = strides[s];
      unsigned char *block = (unsigned char *)malloc(offset + 7 * stride);
      if (!block) {
        exit(EXIT_FAILURE);
      }
      memset(block, 0xFF, offset + 7 * stride);
      for (int i = 0; i < 7; i++) {
        memcpy(block + offset + (size_t)i * stride, &base_v[3 * i], 12);
      }
      d = base_desc();
      d.vertices = (const float *)(const void *)(block + offset);
      d.vertex_stride = stride;
      scene = NULL;
      rq_status st = build(&d, &scene);
      CHECKF(st == RQ_STATUS_OK, "stride %u offset %u: %u (%s)", (unsigned)stride, (unsigned)offset,
             (unsigned)st, rq_status_str(st));
      if (scene) {
        trace_set(scene, got);
        CHECKF(memcmp(ref, got, sizeof ref) == 0, "stride %u offset %u: hits differ from stride 12",
               (unsigned)stride, (unsigned)offset);
        rq_scene_free(scene);
      }
      free(block);
    }
  }

  /* Misaligned index array (every byte offset), indices copied bytewise. */
  for (size_t offset = 0; offset < 4; offset++) {
    unsigned char *block = (unsigned char *)malloc(offset + sizeof base_i);
    if (!block) {
      exit(EXIT_FAILURE);
    }
    memcpy(block + offset, base_i, sizeof base_i);
    d = base_desc();
    d.indices = (const uint32_t *)(const void *)(block + offset);
    scene = NULL;
    CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
    if (scene) {
      trace_set(scene, got);
      CHECKF(memcmp(ref, got, sizeof ref) == 0, "index offset %u: hits differ", (unsigned)offset);
      rq_scene_free(scene);
    }
    free(block);
  }

  /* Vertex and index arrays exactly as long as their counts imply ((count - 1) * stride + 12 bytes
   * of vertices: the last record has no padding), each ending at an inaccessible page: reading past
   * either faults. */
  for (size_t s = 0; s < sizeof strides / sizeof strides[0]; s++) {
    size_t stride = strides[s], bytes = 6 * stride + 12;
    guarded vb = guarded_alloc(bytes), ib = guarded_alloc(sizeof base_i);
    memset(vb.p, 0xFF, bytes);
    for (int i = 0; i < 7; i++) {
      memcpy(vb.p + (size_t)i * stride, &base_v[3 * i], 12);
    }
    memcpy(ib.p, base_i, sizeof base_i);
    d = base_desc();
    d.vertices = (const float *)(const void *)vb.p;
    d.vertex_stride = stride;
    d.indices = (const uint32_t *)(const void *)ib.p;
    scene = NULL;
    CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
    if (scene) {
      trace_set(scene, got);
      CHECKF(memcmp(ref, got, sizeof ref) == 0, "guarded arrays, stride %u: hits differ", (unsigned)stride);
      rq_scene_free(scene);
    }
    guarded_free(&vb);
    guarded_free(&ib);
  }
}

static void test_count_overflow(void) {
  rq_mesh_desc d;
  /* Triangle counts whose byte size (12 per triangle) overflows, with a real (short) index array:
   * the library must refuse before reading. */
  const size_t tri_counts[] = {SIZE_MAX, SIZE_MAX / 2, SIZE_MAX / 12 + 1, SIZE_MAX / 4};
  for (size_t i = 0; i < sizeof tri_counts / sizeof tri_counts[0]; i++) {
    d = base_desc();
    d.triangle_count = tri_counts[i];
    char what[80];
    snprintf(what, sizeof what, "triangle_count %#zx", tri_counts[i]);
    CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, what);
    /* Same with NULL indices: refused either as overflow or as a NULL array, never built. */
    d.indices = NULL;
    rq_scene *out = (rq_scene *)test_sentinel();
    rq_status s = build(&d, &out);
    CHECKF(s == RQ_STATUS_INVALID_MESH || s == RQ_STATUS_NULL_ARGUMENT, "%s with NULL indices: %u (%s)", what,
           (unsigned)s, rq_status_str(s));
    CHECK(out == (rq_scene *)test_sentinel());
  }
  /* vertex_count * stride overflows (or exceeds the address space). */
  struct {
    size_t count, stride;
  } vcases[] = {
      {SIZE_MAX / 12 + 1, 12}, {SIZE_MAX, 12}, {2, SIZE_MAX}, {3, SIZE_MAX / 2}, {SIZE_MAX / 16 + 2, 16},
      {SIZE_MAX / 2, 13},
  };
  for (size_t i = 0; i < sizeof vcases / sizeof vcases[0]; i++) {
    d = base_desc();
    d.vertex_count = vcases[i].count;
    d.vertex_stride = vcases[i].stride;
    char what[96];
    snprintf(what, sizeof what, "vertex_count %#zx stride %#zx", vcases[i].count, vcases[i].stride);
    CHECK_REFUSED(&d, RQ_STATUS_INVALID_MESH, what);
  }
}

static void test_missing_arrays(void) {
  rq_mesh_desc d = base_desc();
  d.vertices = NULL;
  CHECK_REFUSED(&d, RQ_STATUS_NULL_ARGUMENT, "NULL vertices, 7 of them");
  d = base_desc();
  d.indices = NULL;
  CHECK_REFUSED(&d, RQ_STATUS_NULL_ARGUMENT, "NULL indices, 3 triangles");
  d = base_desc();
  d.vertices = NULL;
  d.indices = NULL;
  {
    rq_scene *out = (rq_scene *)test_sentinel();
    rq_status s = build(&d, &out);
    CHECKF(s == RQ_STATUS_NULL_ARGUMENT, "both NULL: %u (%s)", (unsigned)s, rq_status_str(s));
    CHECK(out == (rq_scene *)test_sentinel());
  }
}

static void check_all_miss(const rq_scene *scene, const char *what) {
  uint64_t rng = 5;
  for (int i = 0; i < 200; i++) {
    rq_ray r = make_ray(rng_float(&rng, -2, 2), rng_float(&rng, -2, 2), rng_float(&rng, -2, 2), 0, 0, 0);
    rng_dir(&rng, r.dir);
    rq_hit h;
    memset(&h, 0x11, sizeof h);
    CHECKF(!rq_scene_intersect(scene, &r, &h), "%s: ray %d hit", what, i);
    CHECKF(is_exact_miss(&h), "%s: ray %d: not the exact miss", what, i);
    CHECKF(!rq_scene_occluded(scene, &r), "%s: ray %d occluded", what, i);
  }
  rq_ray all[3];
  rq_hit hits[3];
  for (int i = 0; i < 3; i++) {
    all[i] = make_ray(0.5f, 0.5f, 2.0f, 0.0f, 0.0f, -1.0f);
  }
  all[1].dir[2] = 1.0f;
  CHECK_STATUS(rq_scene_intersect_n(scene, all, hits, 3), RQ_STATUS_OK);
  for (int i = 0; i < 3; i++) {
    CHECKF(is_exact_miss(&hits[i]), "%s: batch ray %d", what, i);
  }
}

static void test_empty(void) {
  float one_vertex[3] = {0, 0, 0};
  uint32_t one_index[3] = {0, 0, 0};
  struct {
    const char *what;
    const float *v;
    size_t nv;
    const uint32_t *i;
  } cases[] = {
      {"NULL arrays", NULL, 0, NULL},
      {"non-NULL arrays", one_vertex, 0, one_index},
      {"vertices, no triangles", base_v, 7, NULL},
      {"vertices and an index pointer, no triangles", base_v, 7, base_i},
  };
  for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
    rq_mesh_desc d;
    d.vertices = cases[c].v;
    d.vertex_count = cases[c].nv;
    d.vertex_stride = 12;
    d.indices = cases[c].i;
    d.triangle_count = 0;
    rq_scene *scene = NULL;
    rq_status s = build(&d, &scene);
    CHECKF(s == RQ_STATUS_OK && scene, "empty mesh (%s): %u (%s)", cases[c].what, (unsigned)s,
           rq_status_str(s));
    if (!scene) {
      continue;
    }
    check_all_miss(scene, cases[c].what);
    rq_scene_report rep;
    memset(&rep, 0, sizeof rep);
    rep.struct_size = (uint32_t)sizeof rep;
    CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
    CHECK(rep.triangle_count == 0);
    rq_scene_free(scene);
  }
  /* An empty mesh under every structure and under a memory limit. */
  rq_mesh_desc d = {NULL, 0, 12, NULL, 0};
  for (int s = 0; s <= 2; s++) {
    rq_build_options o;
    rq_build_options_init(&o);
    o.structure = (rq_structure)s;
    o.memory_limit = 4096;
    rq_scene *scene = NULL;
    rq_status st = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(st == RQ_STATUS_OK,
           "empty mesh, structure %d: %u (%s)", s, (unsigned)st, rq_status_str(st));
    if (scene) {
      check_all_miss(scene, "empty mesh with options");
      rq_scene_free(scene);
    }
  }
}

static void test_degenerate(void) {
  /* Triangles 0..4 are degenerate (repeated index, collinear, all equal, zero-length edge by equal
   * coordinates, tiny collinear); triangle 5 is a real one; 6 is degenerate again. */
  const float v[] = {
      0.0f, 0.0f, 0.0f,  /* 0 */
      1.0f, 0.0f, 0.0f,  /* 1 */
      2.0f, 0.0f, 0.0f,  /* 2: collinear with 0 and 1 */
      0.0f, 1.0f, 0.0f,  /* 3 */
      1.0f, 0.0f, 0.0f,  /* 4: same place as 1 */
      0.5f, 0.5f, 0.0f,  /* 5: on the line from 1 to 3 */
      -4.0f, -4.0f, -1.0f, /* 6 */
      8.0f, -4.0f, -1.0f,  /* 7 */
      -4.0f, 8.0f, -1.0f,  /* 8 */
  };
  const uint32_t idx[] = {
      0, 0, 1, /* repeated index */
      0, 1, 2, /* collinear along x */
      3, 3, 3, /* all three equal */
      1, 4, 3, /* two vertices at the same place */
      1, 5, 3, /* collinear along the diagonal */
      6, 7, 8, /* the real triangle, at z = -1, under all of the above */
      2, 1, 0, /* collinear again, after the real one */
  };
  rq_mesh_desc d;
  d.vertices = v;
  d.vertex_count = 9;
  d.vertex_stride = 12;
  d.indices = idx;
  d.triangle_count = 7;
  rq_scene *scene = NULL;
  CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
  if (!scene) {
    return;
  }
  rq_scene_report rep;
  memset(&rep, 0, sizeof rep);
  rep.struct_size = (uint32_t)sizeof rep;
  CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
  CHECK(rep.triangle_count == 7);
  /* Rays straight down through points on the degenerate triangles (their vertices, edges, midpoints)
   * and oblique rays through the same points: the degenerate ones are never hit, the real one is, with
   * its own id (5: ids are not renumbered around degenerate triangles). */
  const float pts[][2] = {{0, 0}, {1, 0}, {2, 0}, {0.5f, 0}, {1.5f, 0}, {0, 1}, {0.5f, 0.5f}, {0.25f, 0.75f}};
  for (size_t p = 0; p < sizeof pts / sizeof pts[0]; p++) {
    for (int k = 0; k < 4; k++) {
      float dx = k == 1 ? 0.25f : (k == 3 ? -0.125f : 0.0f), dy = k == 2 ? 0.5f : 0.0f;
      rq_ray r = make_ray(pts[p][0] - dx, pts[p][1] - dy, 1.0f, dx, dy, -1.0f);
      rq_hit h;
      CHECKF(rq_scene_intersect(scene, &r, &h), "point %u dir %d: missed the real triangle", (unsigned)p, k);
      CHECKF(h.prim == 5, "point %u dir %d: hit prim %u", (unsigned)p, k, (unsigned)h.prim);
      CHECKF(h.t == 2.0f || fabsf(h.t - 2.0f) < 1e-6f, "point %u dir %d: t %g", (unsigned)p, k, (double)h.t);
      /* With the window ending before the real triangle, nothing is hit. */
      r.tmax = 1.5f;
      CHECKF(!rq_scene_intersect(scene, &r, &h), "point %u dir %d: hit a degenerate triangle (prim %u)",
             (unsigned)p, k, (unsigned)h.prim);
      CHECK(!rq_scene_occluded(scene, &r));
    }
  }
  /* Rays in the plane of the degenerate triangles, along their lines. */
  rq_ray along = make_ray(-5.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f);
  CHECK(!rq_scene_intersect(scene, &along, NULL));
  along = make_ray(1.0f, 0.0f, 0.0f, -1.0f, 1.0f, 0.0f);
  along.org[0] = 2.0f;
  along.org[1] = -1.0f;
  CHECK(!rq_scene_intersect(scene, &along, NULL));
  rq_scene_free(scene);

  /* A mesh of nothing but degenerate triangles: builds, every ray misses. */
  d.triangle_count = 5;
  scene = NULL;
  CHECK_STATUS(build(&d, &scene), RQ_STATUS_OK);
  if (scene) {
    check_all_miss(scene, "all-degenerate mesh");
    rq_scene_free(scene);
  }
}

static void test_memory_limit(void) {
  test_mesh m = mesh_cube(8);
  rq_mesh_desc d = mesh_desc(&m);
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = RQ_STRUCTURE_GRID;

  /* Unlimited, to learn what the scene holds. */
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
  rq_scene_report rep;
  memset(&rep, 0, sizeof rep);
  rep.struct_size = (uint32_t)sizeof rep;
  CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
  size_t need = rep.memory_bytes;
  CHECK(need > 0);
  rq_scene_free(scene);

  /* Tiny limits: refused with MEMORY_LIMIT, *out untouched. */
  const size_t tiny[] = {1, 2, 16, 100, 1000};
  for (size_t i = 0; i < sizeof tiny / sizeof tiny[0]; i++) {
    o.memory_limit = tiny[i];
    scene = (rq_scene *)test_sentinel();
    rq_status s = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(s == RQ_STATUS_MEMORY_LIMIT, "limit %u: %u (%s)", (unsigned)tiny[i], (unsigned)s, rq_status_str(s));
    CHECK(scene == (rq_scene *)test_sentinel());
  }

  /* Just below what the finished scene holds: it cannot be built within the limit. */
  o.memory_limit = need - 1;
  scene = (rq_scene *)test_sentinel();
  {
    rq_status s = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(s == RQ_STATUS_MEMORY_LIMIT, "limit %zu (scene holds %zu): %u (%s)", need - 1, need, (unsigned)s,
           rq_status_str(s));
    if (s == RQ_STATUS_OK) {
      rq_scene_free(scene);
    } else {
      CHECK(scene == (rq_scene *)test_sentinel());
    }
  }

  /* Generous limits: built, and the scene holds no more than the limit. */
  const size_t generous[] = {need * 4, need * 2 + 4096, (size_t)64 << 20, SIZE_MAX};
  for (size_t i = 0; i < sizeof generous / sizeof generous[0]; i++) {
    o.memory_limit = generous[i];
    scene = NULL;
    rq_status s = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(s == RQ_STATUS_OK, "limit %zu: %u (%s)", generous[i], (unsigned)s, rq_status_str(s));
    if (scene) {
      memset(&rep, 0, sizeof rep);
      rep.struct_size = (uint32_t)sizeof rep;
      CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
      CHECKF(rep.memory_bytes > 0 && rep.memory_bytes <= generous[i], "limit %zu, holds %zu", generous[i],
             rep.memory_bytes);
      rq_scene_free(scene);
    }
  }

  /* Some limit between "tiny" and "generous" succeeds exactly when the report fits it: search for
   * the smallest limit that builds, and check the scene it builds fits. */
  size_t lo = 1, hi = need * 4;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    o.memory_limit = mid;
    scene = NULL;
    rq_status s = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(s == RQ_STATUS_OK || s == RQ_STATUS_MEMORY_LIMIT, "limit %zu: %u (%s)", mid, (unsigned)s,
           rq_status_str(s));
    if (s == RQ_STATUS_OK) {
      rq_scene_free(scene);
      hi = mid;
    } else {
      lo = mid + 1;
    }
  }
  CHECKF(lo >= need, "built under a limit of %zu but the scene reports %zu bytes", lo, need);
  mesh_free(&m);
}

int main(void) {
  test_non_finite_vertices();
  test_indices();
  test_strides();
  test_count_overflow();
  test_missing_arrays();
  test_empty();
  test_degenerate();
  test_memory_limit();
  return test_finish("hostile_mesh");
}
