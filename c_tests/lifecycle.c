/* lifecycle.c: the C contract outside the geometry: version macros against the runtime, the numbers
 * of every enum, struct layouts, status strings, build and free, NULL on every function,
 * out-parameters untouched on failure, option defaults and struct_size, and the error callback. */
#include "common.h"

#include <stddef.h>

/* ---- a one-triangle mesh used throughout ------------------------------------------------------ */

static const float tri_vertices[9] = {0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f};
static const uint32_t tri_indices[3] = {0, 1, 2};

static rq_mesh_desc tri_desc(void) {
  rq_mesh_desc d;
  d.vertices = tri_vertices;
  d.vertex_count = 3;
  d.vertex_stride = 12;
  d.indices = tri_indices;
  d.triangle_count = 1;
  return d;
}

/* A ray that hits the triangle at t = 1 and one that misses it. */
static rq_ray hit_ray(void) { return make_ray(0.25f, 0.25f, 1.0f, 0.0f, 0.0f, -1.0f); }
static rq_ray miss_ray(void) { return make_ray(2.0f, 2.0f, 1.0f, 0.0f, 0.0f, -1.0f); }

/* ---- the error callback ----------------------------------------------------------------------- */

typedef struct error_log {
  int calls;
  rq_status status;
  void *user_seen;
  char message[512];
} error_log;

static void on_error(void *user, rq_status status, const char *message) {
  error_log *log = (error_log *)user;
  /* The library may be called from inside the callback. */
  const char *text = rq_status_str(status);
  if (!text || !text[0]) {
    log->calls += 1000;
  }
  log->calls++;
  log->status = status;
  log->user_seen = user;
  if (message) {
    strncpy(log->message, message, sizeof log->message - 1);
    log->message[sizeof log->message - 1] = '\0';
  } else {
    strcpy(log->message, "(NULL message)");
  }
}

/* For builds whose options do not cover `user`: the callback must still be called, with user NULL. */
static int global_calls;
static rq_status global_status;
static void *global_user;
static void on_error_global(void *user, rq_status status, const char *message) {
  global_calls++;
  global_status = status;
  global_user = user;
  (void)message;
}

static void test_versions_and_numbers(void) {
  CHECK(RQ_ABI_VERSION == 1);
  CHECK(rq_abi_version() == RQ_ABI_VERSION);
  const char *v = rq_version_string();
  CHECK(v != NULL);
  if (v) {
    CHECKF(strncmp(v, "rayq ", 5) == 0, "version string is \"%s\"", v);
    CHECKF(v[5] >= '0' && v[5] <= '9', "version string is \"%s\"", v);
    CHECK(rq_version_string() == v || strcmp(rq_version_string(), v) == 0);
  }
  CHECK(RQ_INVALID_ID == 0xFFFFFFFFu);

  /* Numbers that never move (DESIGN §4). */
  CHECK(RQ_STATUS_OK == 0);
  CHECK(RQ_STATUS_NULL_ARGUMENT == 1);
  CHECK(RQ_STATUS_INVALID_ARGUMENT == 2);
  CHECK(RQ_STATUS_INVALID_MESH == 3);
  CHECK(RQ_STATUS_ABI_MISMATCH == 4);
  CHECK(RQ_STATUS_INVALID_OPERATION == 5);
  CHECK(RQ_STATUS_UNSUPPORTED == 6);
  CHECK(RQ_STATUS_OUT_OF_MEMORY == 100);
  CHECK(RQ_STATUS_MEMORY_LIMIT == 101);
  CHECK(RQ_STATUS_CANCELLED == 102);
  CHECK(RQ_STATUS_CALIB_BAD_MAGIC == 200);
  CHECK(RQ_STATUS_CALIB_UNSUPPORTED_VERSION == 201);
  CHECK(RQ_STATUS_CALIB_TRUNCATED == 202);
  CHECK(RQ_STATUS_CALIB_CHECKSUM == 203);
  CHECK(RQ_STATUS_CALIB_VALUE_OUT_OF_RANGE == 204);
  CHECK(RQ_STATUS_OBJ_UNREADABLE == 300);
  CHECK(RQ_STATUS_OBJ_MALFORMED == 301);
  CHECK(RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE == 302);
  CHECK(RQ_STATUS_PANIC == 900);
  CHECK(RQ_STATUS_INTERNAL == 901);
  CHECK(RQ_STRUCTURE_AUTO == 0);
  CHECK(RQ_STRUCTURE_GRID == 1);
  CHECK(RQ_STRUCTURE_KDTREE == 2);
  CHECK(RQ_OUTCOME_FORCED == 0);
  CHECK(RQ_OUTCOME_GRID_FASTER_PER_RAY == 1);
  CHECK(RQ_OUTCOME_BELOW_BREAK_EVEN == 2);
  CHECK(RQ_OUTCOME_ABOVE_BREAK_EVEN == 3);
  CHECK(RQ_OUTCOME_ONLINE_ON_GRID == 4);
  CHECK(RQ_OUTCOME_ONLINE_SWITCHED == 5);
}

static void test_layouts(void) {
  CHECK(sizeof(rq_status) == 4);
  CHECK(sizeof(rq_structure) == 4);
  CHECK(sizeof(rq_outcome) == 4);

  CHECK(sizeof(rq_ray) == 32);
  CHECK(offsetof(rq_ray, org) == 0);
  CHECK(offsetof(rq_ray, tmin) == 12);
  CHECK(offsetof(rq_ray, dir) == 16);
  CHECK(offsetof(rq_ray, tmax) == 28);

  CHECK(sizeof(rq_hit) == 16);
  CHECK(offsetof(rq_hit, t) == 0);
  CHECK(offsetof(rq_hit, u) == 4);
  CHECK(offsetof(rq_hit, v) == 8);
  CHECK(offsetof(rq_hit, prim) == 12);

  /* The rest follow the platform's natural C layout; check the order and the first fields. */
  CHECK(offsetof(rq_mesh_desc, vertices) == 0);
  CHECK(offsetof(rq_mesh_desc, vertex_count) < offsetof(rq_mesh_desc, vertex_stride));
  CHECK(offsetof(rq_mesh_desc, vertex_stride) < offsetof(rq_mesh_desc, indices));
  CHECK(offsetof(rq_mesh_desc, indices) < offsetof(rq_mesh_desc, triangle_count));

  CHECK(offsetof(rq_build_options, struct_size) == 0);
  CHECK(offsetof(rq_build_options, structure) == 4);
  CHECK(offsetof(rq_build_options, expected_rays) == 8);
  CHECK(offsetof(rq_build_options, sample_rays) == 16);
  CHECK(offsetof(rq_build_options, sample_ray_count) > offsetof(rq_build_options, sample_rays));
  CHECK(offsetof(rq_build_options, memory_limit) > offsetof(rq_build_options, sample_ray_count));
  CHECK(offsetof(rq_build_options, on_error) > offsetof(rq_build_options, memory_limit));
  CHECK(offsetof(rq_build_options, user) > offsetof(rq_build_options, on_error));

  CHECK(offsetof(rq_scene_report, struct_size) == 0);
  CHECK(offsetof(rq_scene_report, structure) == 4);
  CHECK(offsetof(rq_scene_report, outcome) == 8);
  CHECK(offsetof(rq_scene_report, triangle_count) > offsetof(rq_scene_report, outcome));
  CHECK(offsetof(rq_scene_report, memory_bytes) > offsetof(rq_scene_report, triangle_count));
  CHECK(offsetof(rq_scene_report, grid_resolution) > offsetof(rq_scene_report, memory_bytes));
  CHECK(offsetof(rq_scene_report, grid_ray_seconds) > offsetof(rq_scene_report, grid_resolution));
  CHECK(offsetof(rq_scene_report, expected_rays) > offsetof(rq_scene_report, break_even_rays));
#if UINTPTR_MAX == UINT64_MAX && SIZE_MAX == UINT64_MAX
  /* LP64 / LLP64: the layouts the Rust side's repr(C) gives, pinned. */
  CHECK(sizeof(rq_mesh_desc) == 40);
  CHECK(sizeof(rq_build_options) == 96);
  CHECK(offsetof(rq_build_options, memory_limit) == 32);
  CHECK(offsetof(rq_build_options, on_error) == 40);
  CHECK(offsetof(rq_build_options, user) == 48);
  CHECK(offsetof(rq_build_options, memory_monitor) == 56);
  CHECK(offsetof(rq_build_options, memory_monitor_user) == 64);
  CHECK(offsetof(rq_build_options, budget_kind) == 72);
  CHECK(offsetof(rq_build_options, clock) == 80);
  CHECK(offsetof(rq_build_options, clock_user) == 88);
  CHECK(offsetof(rq_scene_report, triangle_count) == 16);
  CHECK(offsetof(rq_scene_report, memory_bytes) == 24);
  CHECK(offsetof(rq_scene_report, grid_resolution) == 32);
  CHECK(offsetof(rq_scene_report, grid_ray_seconds) == 48);
  CHECK(offsetof(rq_scene_report, expected_rays) == 80);
  CHECK(offsetof(rq_scene_report, references_per_triangle) == 88);
  CHECK(offsetof(rq_scene_report, kd_node_count) == 96);
  CHECK(offsetof(rq_scene_report, kd_depth) == 104);
  CHECK(offsetof(rq_scene_report, geometry_count) == 112);
  CHECK(sizeof(rq_scene_report) == 120);
  CHECK(sizeof(rq_ray_ex) == 40);
  CHECK(sizeof(rq_hit_ex) == 32);
  CHECK(offsetof(rq_geometry_desc, mesh) == 8);
  CHECK(offsetof(rq_geometry_desc, mask) == 48);
  CHECK(offsetof(rq_geometry_desc, flags) == 52);
  CHECK(offsetof(rq_geometry_desc, filter) == 56);
  CHECK(sizeof(rq_geometry_desc) == 72);
#endif
}

static void test_status_strings(void) {
  static const uint32_t known[] = {0, 1, 2, 3, 4, 5, 6, 100, 101, 102, 200, 201, 202, 203, 204, 300, 301, 302,
                                   900, 901};
  static const uint32_t unknown[] = {7, 8, 99, 103, 199, 205, 299, 303, 899, 902, 1000,
                                     0x7FFFFFFFu, 0x80000000u, UINT32_MAX};
  const size_t nk = sizeof known / sizeof known[0];
  const char *unknown_text = rq_status_str(12345);
  CHECK(unknown_text != NULL && unknown_text[0] != '\0');
  for (size_t i = 0; i < nk; i++) {
    const char *s = rq_status_str(known[i]);
    CHECKF(s != NULL, "rq_status_str(%u) is NULL", (unsigned)known[i]);
    if (!s) {
      continue;
    }
    CHECKF(s[0] != '\0', "rq_status_str(%u) is empty", (unsigned)known[i]);
    CHECKF(!unknown_text || strcmp(s, unknown_text) != 0, "rq_status_str(%u) says \"%s\"", (unsigned)known[i],
           s);
    for (size_t j = 0; j < i; j++) {
      const char *o = rq_status_str(known[j]);
      CHECKF(!o || strcmp(s, o) != 0, "statuses %u and %u share the text \"%s\"", (unsigned)known[i],
             (unsigned)known[j], s);
    }
  }
  for (size_t i = 0; i < sizeof unknown / sizeof unknown[0]; i++) {
    const char *s = rq_status_str(unknown[i]);
    CHECKF(s != NULL && s[0] != '\0', "rq_status_str(%u) is NULL or empty", (unsigned)unknown[i]);
  }
}

static void test_build_and_free(void) {
  rq_mesh_desc d = tri_desc();
  rq_scene *scene = NULL;
  /* NULL options and NULL calibration mean the defaults. */
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  CHECK(scene != NULL);
  rq_hit h;
  rq_ray r = hit_ray();
  CHECK(rq_scene_intersect(scene, &r, &h));
  CHECK(h.prim == 0 && h.t == 1.0f);
  r = miss_ray();
  CHECK(!rq_scene_intersect(scene, &r, &h));
  CHECK(is_exact_miss(&h));
  rq_scene_free(scene);

  /* The built-in calibration passed explicitly; initialised options passed explicitly. */
  rq_build_options o;
  rq_build_options_init(&o);
  scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, rq_calibration_builtin(), &scene), RQ_STATUS_OK);
  CHECK(scene != NULL);
  rq_scene_free(scene);

  /* Many scenes alive at once are independent. */
  rq_scene *many[8];
  for (int i = 0; i < 8; i++) {
    many[i] = NULL;
    CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &many[i]), RQ_STATUS_OK);
  }
  for (int i = 0; i < 8; i++) {
    CHECK(many[i] != NULL);
    for (int j = 0; j < i; j++) {
      CHECK(many[i] != many[j]);
    }
  }
  for (int i = 7; i >= 0; i--) {
    rq_scene_free(many[i]);
  }

  /* Every _free accepts NULL. */
  rq_scene_free(NULL);
  rq_calibration_free(NULL);
  /* ... and freeing the built-in calibration is a no-op: it stays usable. */
  rq_calibration_free((rq_calibration *)rq_calibration_builtin());
  scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, rq_calibration_builtin(), &scene), RQ_STATUS_OK);
  rq_scene_free(scene);
  rq_build_options_init(NULL);
#if defined(RQ_WITH_OBJ)
  rq_obj_free(NULL);
#endif
}

static void test_null_arguments(void) {
  rq_mesh_desc d = tri_desc();
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  if (!scene) {
    return;
  }
  rq_ray r = hit_ray();
  rq_hit h;

  /* rq_scene_build: NULL mesh or NULL out; out untouched. */
  rq_scene *out = (rq_scene *)test_sentinel();
  CHECK_STATUS(rq_scene_build(NULL, NULL, NULL, &out), RQ_STATUS_NULL_ARGUMENT);
  CHECK(out == (rq_scene *)test_sentinel());
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_build(NULL, NULL, NULL, NULL), RQ_STATUS_NULL_ARGUMENT);

  /* rq_scene_intersect: a NULL scene or ray is a miss, and *out is still written (as the miss). */
  memset(&h, 0xCD, sizeof h);
  CHECK(!rq_scene_intersect(NULL, &r, &h));
  CHECK(is_exact_miss(&h));
  memset(&h, 0xCD, sizeof h);
  CHECK(!rq_scene_intersect(scene, NULL, &h));
  CHECK(is_exact_miss(&h));
  CHECK(!rq_scene_intersect(NULL, NULL, NULL));
  /* A NULL out still answers. */
  CHECK(rq_scene_intersect(scene, &r, NULL));
  rq_ray m = miss_ray();
  CHECK(!rq_scene_intersect(scene, &m, NULL));

  /* rq_scene_occluded. */
  CHECK(!rq_scene_occluded(NULL, &r));
  CHECK(!rq_scene_occluded(scene, NULL));
  CHECK(!rq_scene_occluded(NULL, NULL));
  CHECK(rq_scene_occluded(scene, &r));

  /* rq_scene_intersect_n: NULL arrays are refused when n > 0, and hits are left untouched. */
  rq_hit hits[2], before[2];
  rq_ray rays[2];
  rays[0] = hit_ray();
  rays[1] = miss_ray();
  memset(hits, 0xCD, sizeof hits);
  memcpy(before, hits, sizeof hits);
  CHECK_STATUS(rq_scene_intersect_n(NULL, rays, hits, 2), RQ_STATUS_NULL_ARGUMENT);
  CHECK(memcmp(hits, before, sizeof hits) == 0);
  CHECK_STATUS(rq_scene_intersect_n(scene, NULL, hits, 2), RQ_STATUS_NULL_ARGUMENT);
  CHECK(memcmp(hits, before, sizeof hits) == 0);
  CHECK_STATUS(rq_scene_intersect_n(scene, rays, NULL, 2), RQ_STATUS_NULL_ARGUMENT);
  /* n == 0 is a no-op: NULL arrays are fine then. */
  CHECK_STATUS(rq_scene_intersect_n(scene, NULL, NULL, 0), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_intersect_n(scene, rays, hits, 0), RQ_STATUS_OK);
  CHECK(memcmp(hits, before, sizeof hits) == 0);
  {
    /* A NULL scene is refused even with n == 0 (documented in the header). */
    rq_status s = rq_scene_intersect_n(NULL, NULL, NULL, 0);
    CHECKF(s == RQ_STATUS_NULL_ARGUMENT, "got %u (%s)", (unsigned)s, rq_status_str(s));
  }
  CHECK_STATUS(rq_scene_intersect_n(scene, rays, hits, 2), RQ_STATUS_OK);
  CHECK(hits[0].prim == 0 && is_exact_miss(&hits[1]));

  /* rq_scene_report_get: NULL scene or out; the report is untouched on failure. */
  rq_scene_report rep, rep_before;
  memset(&rep, 0xAB, sizeof rep);
  rep.struct_size = (uint32_t)sizeof rep;
  memcpy(&rep_before, &rep, sizeof rep);
  CHECK_STATUS(rq_scene_report_get(NULL, &rep), RQ_STATUS_NULL_ARGUMENT);
  CHECK(memcmp(&rep, &rep_before, sizeof rep) == 0);
  CHECK_STATUS(rq_scene_report_get(scene, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_report_get(NULL, NULL), RQ_STATUS_NULL_ARGUMENT);

  /* rq_scene_update. */
  CHECK_STATUS(rq_scene_update(NULL, 10, 10), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_update(scene, 10, 0), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_update(scene, UINT64_MAX, UINT64_MAX), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_update(scene, UINT64_MAX, 0), RQ_STATUS_OK);
  /* The scene still answers the same after updates. */
  CHECK(rq_scene_intersect(scene, &r, &h) && h.prim == 0 && h.t == 1.0f);

  /* Calibration functions. */
  const rq_calibration *builtin = rq_calibration_builtin();
  CHECK(builtin != NULL);
  CHECK(rq_calibration_builtin() == builtin);
  unsigned char blob[4096], blob_before[4096];
  memset(blob, 0x5A, sizeof blob);
  memcpy(blob_before, blob, sizeof blob);
  size_t written = 777;
  rq_calibration *cal = (rq_calibration *)test_sentinel();
  CHECK_STATUS(rq_calibration_from_bytes(NULL, 64, &cal), RQ_STATUS_NULL_ARGUMENT);
  CHECK(cal == (rq_calibration *)test_sentinel());
  CHECK_STATUS(rq_calibration_from_bytes(blob, sizeof blob, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_calibration_to_bytes(NULL, blob, sizeof blob, &written), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_calibration_to_bytes(builtin, NULL, sizeof blob, &written), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_calibration_to_bytes(builtin, blob, sizeof blob, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK(written == 777);
  CHECK(memcmp(blob, blob_before, sizeof blob) == 0);

#if defined(RQ_WITH_OBJ)
  /* OBJ helper. */
  rq_obj *obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load(NULL, &obj), RQ_STATUS_NULL_ARGUMENT);
  CHECK(obj == (rq_obj *)test_sentinel());
  CHECK_STATUS(rq_obj_load("does-not-matter.obj", NULL), RQ_STATUS_NULL_ARGUMENT);
  rq_mesh_desc desc, desc_before;
  memset(&desc, 0x3C, sizeof desc);
  memcpy(&desc_before, &desc, sizeof desc);
  CHECK_STATUS(rq_obj_mesh_desc(NULL, &desc), RQ_STATUS_NULL_ARGUMENT);
  CHECK(memcmp(&desc, &desc_before, sizeof desc) == 0);
  float lo[3] = {7.0f, 7.0f, 7.0f}, hi[3] = {7.0f, 7.0f, 7.0f};
  CHECK_STATUS(rq_obj_bounds(NULL, lo, hi), RQ_STATUS_NULL_ARGUMENT);
  CHECK(lo[0] == 7.0f && hi[2] == 7.0f);
#endif

  rq_scene_free(scene);
}

/* rq_scene_intersect_n reads exactly n rays and writes exactly n hits: both arrays end at an
 * inaccessible page. */
static void test_batch_bounds(void) {
  rq_mesh_desc d = tri_desc();
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  if (!scene) {
    return;
  }
  for (size_t n = 1; n <= 9; n++) {
    guarded rb = guarded_alloc(n * sizeof(rq_ray)), hb = guarded_alloc(n * sizeof(rq_hit));
    rq_ray *rays = (rq_ray *)(void *)rb.p;
    rq_hit *hits = (rq_hit *)(void *)hb.p;
    for (size_t i = 0; i < n; i++) {
      rays[i] = i % 2 ? miss_ray() : hit_ray();
    }
    CHECK_STATUS(rq_scene_intersect_n(scene, rays, hits, n), RQ_STATUS_OK);
    for (size_t i = 0; i < n; i++) {
      CHECKF(i % 2 ? is_exact_miss(&hits[i]) : hits[i].prim == 0, "n %zu: hit %zu", n, i);
    }
    rq_hit one;
    CHECK(rq_scene_intersect(scene, &rays[n - 1], &one) == ((n - 1) % 2 == 0));
    CHECK(rq_scene_intersect(scene, &rays[n - 1], &hits[n - 1]) == ((n - 1) % 2 == 0));
    CHECK(rq_scene_occluded(scene, &rays[n - 1]) == ((n - 1) % 2 == 0));
    guarded_free(&rb);
    guarded_free(&hb);
  }
  rq_scene_free(scene);
}

static void test_options_init(void) {
  rq_build_options o;
  memset(&o, 0xAB, sizeof o);
  rq_build_options_init(&o);
  CHECK(o.struct_size == sizeof(rq_build_options));
  CHECK(o.structure == RQ_STRUCTURE_AUTO);
  CHECK(o.expected_rays == 0);
  CHECK(o.sample_rays == NULL);
  CHECK(o.sample_ray_count == 0);
  CHECK(o.memory_limit == 0);
  CHECK(o.on_error == NULL);
  CHECK(o.user == NULL);
}

/* The build options as the first header declared them (DESIGN.md §4): what a program compiled then
 * holds, however many fields were appended since. */
typedef struct first_build_options {
  uint32_t struct_size;
  uint32_t structure;
  uint64_t expected_rays;
  const rq_ray *sample_rays;
  size_t sample_ray_count;
  size_t memory_limit;
  void (*on_error)(void *, rq_status, const char *);
  void *user;
} first_build_options;

/* Checks the defaults of a first-layout struct, `size` bytes written. */
static void check_first_defaults(const first_build_options *o, size_t size, const char *what) {
  CHECKF(o->struct_size == size, "%s: struct_size %u, expected %zu", what, (unsigned)o->struct_size, size);
  CHECKF(o->structure == RQ_STRUCTURE_AUTO && o->expected_rays == 0 && o->sample_rays == NULL &&
             o->sample_ray_count == 0 && o->memory_limit == 0 && o->on_error == NULL && o->user == NULL,
         "%s: not the defaults", what);
}

/* A program compiled against an older, shorter struct: neither the unsized symbol (what such a
 * program calls) nor the sized one writes past its end, and what they leave builds a scene. */
static void test_older_struct_init(void) {
  /* At the end of a page followed by an inaccessible one: a write past the struct faults. */
  guarded g = guarded_alloc(sizeof(first_build_options));
  first_build_options *o = (first_build_options *)(void *)g.p;
  memset(o, 0xAB, sizeof *o);
  (rq_build_options_init)((rq_build_options *)(void *)o); /* the symbol, not the header's macro */
  check_first_defaults(o, sizeof *o, "the unsized symbol");
  memset(o, 0xAB, sizeof *o);
  rq_build_options_init_sized((rq_build_options *)(void *)o, sizeof *o);
  check_first_defaults(o, sizeof *o, "the sized entry");
  o->structure = RQ_STRUCTURE_KDTREE;
  rq_mesh_desc d = tri_desc();
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, (const rq_build_options *)(const void *)o, NULL, &scene), RQ_STATUS_OK);
  if (scene) {
    rq_ray r = hit_ray();
    rq_hit h;
    CHECK(rq_scene_intersect(scene, &r, &h) && h.prim == 0);
    rq_scene_report rep;
    memset(&rep, 0, sizeof rep);
    rep.struct_size = sizeof rep;
    CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
    CHECK(rep.structure == RQ_STRUCTURE_KDTREE);
    rq_scene_free(scene);
  }
  guarded_free(&g);
  /* Too small to hold struct_size: nothing written. */
  unsigned char bytes[8];
  memset(bytes, 0xAB, sizeof bytes);
  rq_build_options_init_sized((rq_build_options *)(void *)bytes, 3);
  int untouched = 1;
  for (size_t i = 0; i < sizeof bytes; i++) {
    untouched &= bytes[i] == 0xAB;
  }
  CHECK(untouched);
  /* A struct as large as this header's, or larger: this header's bytes, no more. */
  struct {
    rq_build_options o;
    unsigned char after[16];
  } big;
  memset(&big, 0xAB, sizeof big);
  rq_build_options_init_sized(&big.o, sizeof big);
  CHECK(big.o.struct_size == sizeof big.o);
  CHECK(big.after[0] == 0xAB && big.after[15] == 0xAB);
  /* The geometry description's unsized symbol writes its first layout, today the whole struct. */
  rq_geometry_desc gd;
  memset(&gd, 0xAB, sizeof gd);
  (rq_geometry_desc_init)(&gd);
  CHECK(gd.struct_size == sizeof gd && gd.mask == 0xFFFFFFFFu && gd.filter == NULL);
}

/* Builds the triangle with options whose first `size` bytes are those of `full`, in a guarded block
 * of exactly that many bytes, so reading a field that `size` does not cover faults. */
static rq_status build_with_size(const rq_build_options *full, uint32_t size, rq_scene **out) {
  size_t bytes = size < 4 ? 4 : size; /* struct_size itself is always there */
  guarded block = guarded_alloc(bytes);
  rq_build_options copy = *full;
  copy.struct_size = size;
  memcpy(block.p, &copy, bytes < sizeof copy ? bytes : sizeof copy);
  rq_mesh_desc d = tri_desc();
  rq_status s = rq_scene_build(&d, (const rq_build_options *)(const void *)block.p, NULL, out);
  guarded_free(&block);
  return s;
}

static void test_options_struct_size(void) {
  rq_build_options o;
  rq_build_options_init(&o);
  const uint32_t full = (uint32_t)sizeof o;
  const uint32_t end_structure = (uint32_t)(offsetof(rq_build_options, structure) + sizeof(rq_structure));
  const uint32_t end_expected = (uint32_t)(offsetof(rq_build_options, expected_rays) + sizeof(uint64_t));
  const uint32_t end_limit = (uint32_t)(offsetof(rq_build_options, memory_limit) + sizeof(size_t));
  const uint32_t end_on_error = (uint32_t)(offsetof(rq_build_options, on_error) + sizeof(rq_error_fn));
  rq_scene *scene;

  /* Too small to hold `structure`: refused, out untouched. */
  static const uint32_t too_small[] = {0, 1, 4, 7};
  for (size_t i = 0; i < sizeof too_small / sizeof too_small[0]; i++) {
    scene = (rq_scene *)test_sentinel();
    rq_status s = build_with_size(&o, too_small[i], &scene);
    CHECKF(s == RQ_STATUS_INVALID_ARGUMENT, "struct_size %u: %u (%s)", (unsigned)too_small[i], (unsigned)s,
           rq_status_str(s));
    CHECK(scene == (rq_scene *)test_sentinel());
  }

  /* Every size from "just structure" to the full struct works (and reads no byte beyond it). */
  for (uint32_t size = end_structure; size <= full; size++) {
    scene = NULL;
    rq_status s = build_with_size(&o, size, &scene);
    CHECKF(s == RQ_STATUS_OK, "struct_size %u: %u (%s)", (unsigned)size, (unsigned)s, rq_status_str(s));
    rq_scene_free(scene);
  }

  /* A structure value out of range is refused whenever struct_size covers it. */
  rq_build_options bad = o;
  bad.structure = (rq_structure)3;
  for (uint32_t size = end_structure; size <= full; size += 4) {
    scene = (rq_scene *)test_sentinel();
    CHECK_STATUS(build_with_size(&bad, size, &scene), RQ_STATUS_INVALID_ARGUMENT);
    CHECK(scene == (rq_scene *)test_sentinel());
  }
  bad.structure = (rq_structure)0xFFFFFFFFu;
  scene = (rq_scene *)test_sentinel();
  CHECK_STATUS(rq_scene_build(&(rq_mesh_desc){tri_vertices, 3, 12, tri_indices, 1}, &bad, NULL, &scene),
               RQ_STATUS_INVALID_ARGUMENT);
  CHECK(scene == (rq_scene *)test_sentinel());

  /* A field is read only when covered: a 1-byte memory limit fails the build exactly when the size
   * covers memory_limit. */
  rq_build_options tiny = o;
  tiny.memory_limit = 1;
  scene = (rq_scene *)test_sentinel();
  CHECK_STATUS(build_with_size(&tiny, end_limit, &scene), RQ_STATUS_MEMORY_LIMIT);
  CHECK(scene == (rq_scene *)test_sentinel());
  scene = NULL;
  CHECK_STATUS(build_with_size(&tiny, end_limit - 1, &scene), RQ_STATUS_OK);
  rq_scene_free(scene);

  /* expected_rays is echoed in the report only when covered. */
  rq_build_options budget = o;
  budget.structure = RQ_STRUCTURE_GRID;
  budget.expected_rays = 123456789;
  for (int covered = 0; covered <= 1; covered++) {
    scene = NULL;
    CHECK_STATUS(build_with_size(&budget, covered ? end_expected : end_expected - 1, &scene), RQ_STATUS_OK);
    if (scene) {
      rq_scene_report rep;
      memset(&rep, 0, sizeof rep);
      rep.struct_size = (uint32_t)sizeof rep;
      CHECK_STATUS(rq_scene_report_get(scene, &rep), RQ_STATUS_OK);
      CHECKF(rep.expected_rays == (covered ? 123456789u : 0u), "covered %d: expected_rays %llu", covered,
             (unsigned long long)rep.expected_rays);
      CHECK(rep.structure == RQ_STRUCTURE_GRID);
    }
    rq_scene_free(scene);
  }

  /* on_error is called only when covered; `user` defaults to NULL when not covered. */
  rq_build_options cb = o;
  cb.structure = (rq_structure)77;
  cb.on_error = on_error_global;
  cb.user = (void *)&global_calls;
  global_calls = 0;
  scene = NULL;
  CHECK_STATUS(build_with_size(&cb, end_on_error - 1, &scene), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(global_calls == 0);
  CHECK_STATUS(build_with_size(&cb, end_on_error, &scene), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(global_calls == 1 && global_status == RQ_STATUS_INVALID_ARGUMENT && global_user == NULL);
  global_calls = 0;
  CHECK_STATUS(build_with_size(&cb, full, &scene), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(global_calls == 1 && global_user == (void *)&global_calls);
  CHECK(scene == NULL);

  /* sample_rays NULL with a non-zero count is refused; real sample rays are accepted. */
  rq_build_options samples = o;
  samples.sample_rays = NULL;
  samples.sample_ray_count = 4;
  scene = (rq_scene *)test_sentinel();
  CHECK_STATUS(build_with_size(&samples, full, &scene), RQ_STATUS_NULL_ARGUMENT);
  CHECK(scene == (rq_scene *)test_sentinel());
  rq_ray sample[3];
  sample[0] = hit_ray();
  sample[1] = miss_ray();
  sample[2] = make_ray(0.1f, 0.1f, -1.0f, 0.0f, 0.0f, 1.0f);
  samples.sample_rays = sample;
  samples.sample_ray_count = 3;
  scene = NULL;
  CHECK_STATUS(build_with_size(&samples, full, &scene), RQ_STATUS_OK);
  rq_scene_free(scene);
  /* Sample rays are hints: NaN, zero and infinite ones do not make the build fail. */
  rq_ray junk[4];
  junk[0] = make_ray(NAN, 0, 0, 0, 0, -1);
  junk[1] = make_ray(0, 0, 1, 0, 0, 0);
  junk[2] = make_ray(INFINITY, 0, 0, -1, 0, 0);
  junk[3] = hit_ray();
  junk[3].tmin = 5.0f;
  junk[3].tmax = 1.0f;
  samples.sample_rays = junk;
  samples.sample_ray_count = 4;
  for (int s = RQ_STRUCTURE_AUTO; s <= RQ_STRUCTURE_GRID; s++) {
    samples.structure = (rq_structure)s;
    samples.expected_rays = s == RQ_STRUCTURE_AUTO ? 1000000 : 0;
    scene = NULL;
    CHECK_STATUS(build_with_size(&samples, full, &scene), RQ_STATUS_OK);
    rq_scene_free(scene);
  }

  /* A larger struct_size (options from a newer header): the known fields are used and the rest
   * ignored, or the options are refused as a whole; never a crash, never *out on failure. */
  struct {
    rq_build_options options;
    unsigned char newer_fields[64];
  } bigger;
  memset(&bigger, 0xFF, sizeof bigger);
  rq_build_options_init(&bigger.options);
  bigger.options.struct_size = (uint32_t)sizeof bigger;
  bigger.options.structure = RQ_STRUCTURE_GRID;
  scene = (rq_scene *)test_sentinel();
  rq_mesh_desc d = tri_desc();
  rq_status st = rq_scene_build(&d, &bigger.options, NULL, &scene);
  /* A struct from a newer header: the fields this library knows are read, the rest ignored. */
  CHECKF(st == RQ_STATUS_OK, "struct_size %u: %u (%s)", (unsigned)bigger.options.struct_size, (unsigned)st,
         rq_status_str(st));
  if (st == RQ_STATUS_OK) {
    rq_scene_free(scene);
  } else {
    CHECK(scene == (rq_scene *)test_sentinel());
  }
}

/* The fields of rq_scene_report after struct_size, for byte-level checks. */
#define REPORT_FIELD(name) {#name, offsetof(rq_scene_report, name), sizeof(((rq_scene_report *)0)->name)}
static const struct {
  const char *name;
  size_t offset, size;
} report_fields[] = {
    REPORT_FIELD(structure),        REPORT_FIELD(outcome),          REPORT_FIELD(triangle_count),
    REPORT_FIELD(memory_bytes),     REPORT_FIELD(grid_resolution),  REPORT_FIELD(grid_ray_seconds),
    REPORT_FIELD(kd_ray_seconds),   REPORT_FIELD(kd_build_seconds), REPORT_FIELD(break_even_rays),
    REPORT_FIELD(expected_rays),    REPORT_FIELD(references_per_triangle), REPORT_FIELD(kd_node_count),
    REPORT_FIELD(kd_depth),
};

static void test_report_struct_size(void) {
  rq_mesh_desc d = tri_desc();
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = RQ_STRUCTURE_GRID;
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
  if (!scene) {
    return;
  }
  rq_scene_report full, part;
  memset(&full, 0, sizeof full);
  full.struct_size = (uint32_t)sizeof full;
  CHECK_STATUS(rq_scene_report_get(scene, &full), RQ_STATUS_OK);
  CHECK(full.struct_size == sizeof full);
  CHECK(full.structure == RQ_STRUCTURE_GRID);
  CHECK(full.triangle_count == 1);

  /* Too small to cover `structure`: refused, nothing written. */
  static const uint32_t too_small[] = {0, 4, 7};
  for (size_t i = 0; i < sizeof too_small / sizeof too_small[0]; i++) {
    memset(&part, 0xAB, sizeof part);
    part.struct_size = too_small[i];
    rq_scene_report before = part;
    rq_status s = rq_scene_report_get(scene, &part);
    CHECKF(s == RQ_STATUS_INVALID_ARGUMENT, "struct_size %u: %u (%s)", (unsigned)too_small[i], (unsigned)s,
           rq_status_str(s));
    CHECK(memcmp(&part, &before, sizeof part) == 0);
  }

  /* Covering up to memory_bytes: those fields written, everything after untouched. */
  const size_t end_memory = offsetof(rq_scene_report, memory_bytes) + sizeof(size_t);
  memset(&part, 0xAB, sizeof part);
  part.struct_size = (uint32_t)end_memory;
  rq_scene_report before = part;
  CHECK_STATUS(rq_scene_report_get(scene, &part), RQ_STATUS_OK);
  CHECK(part.struct_size == end_memory);
  CHECK(part.structure == full.structure);
  CHECK(part.outcome == full.outcome);
  CHECK(part.triangle_count == full.triangle_count);
  CHECK(part.memory_bytes == full.memory_bytes);
  CHECK(memcmp((const unsigned char *)&part + end_memory, (const unsigned char *)&before + end_memory,
               sizeof part - end_memory) == 0);

  /* A size that covers half a field leaves that field alone. */
  memset(&part, 0xAB, sizeof part);
  part.struct_size = (uint32_t)(offsetof(rq_scene_report, triangle_count) + 2);
  before = part;
  CHECK_STATUS(rq_scene_report_get(scene, &part), RQ_STATUS_OK);
  CHECK(part.structure == full.structure && part.outcome == full.outcome);
  CHECK(memcmp(&part.triangle_count, &before.triangle_count, sizeof part - offsetof(rq_scene_report, triangle_count)) ==
        0);

  /* Every size, in a guarded block of exactly that size: a write beyond it faults. */
  for (uint32_t size = 4; size <= sizeof full; size++) {
    guarded block = guarded_alloc(size);
    memset(block.p, 0xEE, size);
    memcpy(block.p, &size, sizeof size);
    rq_status s = rq_scene_report_get(scene, (rq_scene_report *)(void *)block.p);
    CHECKF(s == (size < 8 ? RQ_STATUS_INVALID_ARGUMENT : RQ_STATUS_OK), "struct_size %u: %u (%s)", (unsigned)size,
           (unsigned)s, rq_status_str(s));
    uint32_t size_after;
    memcpy(&size_after, block.p, sizeof size_after);
    CHECK(size_after == size);
    /* Each field is written whole when covered and left alone when not. */
    for (size_t f = 0; s == RQ_STATUS_OK && f < sizeof report_fields / sizeof report_fields[0]; f++) {
      size_t at = report_fields[f].offset, n = report_fields[f].size;
      int covered = at + n <= size;
      for (size_t k = at; k < at + n && k < size; k++) {
        unsigned char expect = covered ? ((const unsigned char *)&full)[k] : 0xEE;
        CHECKF(block.p[k] == expect, "struct_size %u: field %s byte %u is %#x, expected %#x", (unsigned)size,
               report_fields[f].name, (unsigned)(k - at), (unsigned)block.p[k], (unsigned)expect);
      }
    }
    guarded_free(&block);
  }

  /* A larger struct_size (a newer header) is served: the known fields are written. */
  struct {
    rq_scene_report report;
    unsigned char newer_fields[32];
  } bigger;
  memset(&bigger, 0xAB, sizeof bigger);
  bigger.report.struct_size = (uint32_t)sizeof bigger;
  CHECK_STATUS(rq_scene_report_get(scene, &bigger.report), RQ_STATUS_OK);
  CHECK(bigger.report.triangle_count == 1 && bigger.report.structure == RQ_STRUCTURE_GRID);
  CHECK(bigger.newer_fields[0] == 0xAB && bigger.newer_fields[31] == 0xAB);
  rq_scene_free(scene);
}

static void test_error_callback(void) {
  rq_mesh_desc d = tri_desc();
  error_log log;
  rq_build_options o;
  rq_build_options_init(&o);
  o.on_error = on_error;
  o.user = &log;
  rq_scene *scene;

  /* Success: never called. */
  memset(&log, 0, sizeof log);
  scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
  CHECK(log.calls == 0);
  rq_scene_free(scene);

  /* Each failure: called once, with the status returned, the user pointer and a message. */
  struct {
    const char *what;
    rq_mesh_desc mesh;
    int null_mesh, null_out;
    rq_structure structure;
    size_t memory_limit;
    rq_status expected;
  } cases[6];
  memset(cases, 0, sizeof cases);
  static const float nan_vertices[9] = {0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
  float *nan_copy = (float *)malloc(sizeof nan_vertices);
  if (!nan_copy) {
    exit(EXIT_FAILURE);
  }
  memcpy(nan_copy, nan_vertices, sizeof nan_vertices);
  nan_copy[7] = NAN;
  static const uint32_t bad_index[3] = {0, 1, 3};
  cases[0].what = "NULL mesh";
  cases[0].null_mesh = 1;
  cases[0].expected = RQ_STATUS_NULL_ARGUMENT;
  cases[1].what = "NULL out";
  cases[1].mesh = d;
  cases[1].null_out = 1;
  cases[1].expected = RQ_STATUS_NULL_ARGUMENT;
  cases[2].what = "NaN vertex";
  cases[2].mesh = d;
  cases[2].mesh.vertices = nan_copy;
  cases[2].expected = RQ_STATUS_INVALID_MESH;
  cases[3].what = "index out of range";
  cases[3].mesh = d;
  cases[3].mesh.indices = bad_index;
  cases[3].expected = RQ_STATUS_INVALID_MESH;
  cases[4].what = "structure out of range";
  cases[4].mesh = d;
  cases[4].structure = (rq_structure)9;
  cases[4].expected = RQ_STATUS_INVALID_ARGUMENT;
  cases[5].what = "memory limit";
  cases[5].mesh = d;
  cases[5].memory_limit = 1;
  cases[5].expected = RQ_STATUS_MEMORY_LIMIT;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    memset(&log, 0, sizeof log);
    o.structure = cases[i].structure;
    o.memory_limit = cases[i].memory_limit;
    scene = (rq_scene *)test_sentinel();
    rq_status s = rq_scene_build(cases[i].null_mesh ? NULL : &cases[i].mesh, &o, NULL,
                                 cases[i].null_out ? NULL : &scene);
    CHECKF(s == cases[i].expected, "%s: %u (%s)", cases[i].what, (unsigned)s, rq_status_str(s));
    CHECKF(log.calls == 1, "%s: on_error called %d times", cases[i].what, log.calls);
    CHECKF(log.status == s, "%s: on_error told %u, build returned %u", cases[i].what, (unsigned)log.status,
           (unsigned)s);
    CHECKF(log.user_seen == &log, "%s: user pointer not passed", cases[i].what);
    CHECKF(log.message[0] != '\0', "%s: empty message", cases[i].what);
    CHECK(scene == (rq_scene *)test_sentinel());
    if (s != RQ_STATUS_OK && scene != (rq_scene *)test_sentinel()) {
      rq_scene_free(scene);
    }
  }
  free(nan_copy);
}

int main(void) {
  test_versions_and_numbers();
  test_layouts();
  test_status_strings();
  test_build_and_free();
  test_null_arguments();
  test_batch_bounds();
  test_options_init();
  test_older_struct_init();
  test_options_struct_size();
  test_report_struct_size();
  test_error_callback();
  return test_finish("lifecycle");
}
