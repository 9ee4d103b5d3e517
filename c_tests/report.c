/* report.c: what rq_scene_report_get says must make sense: the structure in use, why, how many
 * triangles, the grid's resolution, the memory held, the estimates, and the ray budget. */
#include "common.h"

/* An estimate is NaN (not estimated) or a finite non-negative number. */
static int estimate_ok(double x) { return isnan(x) || (isfinite(x) && x >= 0.0); }

static void check_common(const rq_scene_report *r, size_t triangles, const char *what) {
  CHECKF(r->struct_size == sizeof *r, "%s: struct_size changed to %u", what, (unsigned)r->struct_size);
  CHECKF(r->structure == RQ_STRUCTURE_GRID || r->structure == RQ_STRUCTURE_KDTREE, "%s: structure %u", what,
         (unsigned)r->structure);
  CHECKF(r->outcome <= RQ_OUTCOME_ONLINE_SWITCHED, "%s: outcome %u", what, (unsigned)r->outcome);
  CHECKF(r->triangle_count == triangles, "%s: triangle_count %zu, expected %zu", what, r->triangle_count, triangles);
  CHECKF(estimate_ok(r->grid_ray_seconds), "%s: grid_ray_seconds %g", what, r->grid_ray_seconds);
  CHECKF(estimate_ok(r->kd_ray_seconds), "%s: kd_ray_seconds %g", what, r->kd_ray_seconds);
  CHECKF(estimate_ok(r->kd_build_seconds), "%s: kd_build_seconds %g", what, r->kd_build_seconds);
  CHECKF(isnan(r->break_even_rays) || r->break_even_rays >= 0.0, "%s: break_even_rays %g", what,
         r->break_even_rays);
  CHECKF(isnan(r->references_per_triangle) || r->references_per_triangle >= 0.0, "%s: references_per_triangle %g",
         what, r->references_per_triangle);
  /* The outcome and the structure tell the same story. */
  if (r->structure == RQ_STRUCTURE_KDTREE) {
    CHECKF(r->outcome == RQ_OUTCOME_FORCED || r->outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN ||
               r->outcome == RQ_OUTCOME_ONLINE_SWITCHED,
           "%s: on the kd-tree with outcome %u", what, (unsigned)r->outcome);
  } else {
    CHECKF(r->outcome != RQ_OUTCOME_ABOVE_BREAK_EVEN && r->outcome != RQ_OUTCOME_ONLINE_SWITCHED,
           "%s: on the grid with outcome %u", what, (unsigned)r->outcome);
  }
}

static void test_grid_report(void) {
  const int sizes[] = {1, 3, 10};
  for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
    test_mesh m = mesh_cube(sizes[i]);
    rq_build_options o;
    rq_build_options_init(&o);
    o.structure = RQ_STRUCTURE_GRID;
    o.expected_rays = 1000;
    rq_mesh_desc d = mesh_desc(&m);
    rq_scene *scene = NULL;
    CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
    if (!scene) {
      mesh_free(&m);
      continue;
    }
    rq_scene_report r = test_report(scene);
    check_common(&r, m.nt, "grid");
    CHECK(r.structure == RQ_STRUCTURE_GRID);
    CHECK(r.outcome == RQ_OUTCOME_FORCED);
    CHECK(r.expected_rays == 1000);
    CHECKF(r.grid_resolution[0] > 0 && r.grid_resolution[1] > 0 && r.grid_resolution[2] > 0,
           "cube %d: resolution %u x %u x %u", sizes[i], (unsigned)r.grid_resolution[0],
           (unsigned)r.grid_resolution[1], (unsigned)r.grid_resolution[2]);
    /* A grid has at most a few cells per triangle per axis; a cube is symmetric. */
    uint64_t cells = (uint64_t)r.grid_resolution[0] * r.grid_resolution[1] * r.grid_resolution[2];
    CHECKF(cells <= 64 * (uint64_t)m.nt + 64, "cube %d: %llu cells for %zu triangles", sizes[i],
           (unsigned long long)cells, m.nt);
    CHECK(r.grid_resolution[0] == r.grid_resolution[1] && r.grid_resolution[1] == r.grid_resolution[2]);
    /* The build copies what it needs: at least the coordinates of every vertex the triangles use. */
    CHECKF(r.memory_bytes >= m.nv * 12, "cube %d: memory_bytes %zu for %zu vertices", sizes[i], r.memory_bytes,
           m.nv);
    CHECKF(r.memory_bytes < (size_t)1 << 30, "cube %d: memory_bytes %zu", sizes[i], r.memory_bytes);
    /* Every triangle sits in at least one cell. */
    CHECKF(r.references_per_triangle >= 1.0, "cube %d: references_per_triangle %g", sizes[i],
           r.references_per_triangle);
    rq_scene_free(scene);
    mesh_free(&m);
  }

  /* Memory grows with the mesh. */
  size_t prev = 0;
  for (int n = 2; n <= 32; n *= 2) {
    test_mesh m = mesh_plane(n);
    rq_scene *scene = test_build(&m, RQ_STRUCTURE_GRID);
    if (scene) {
      rq_scene_report r = test_report(scene);
      check_common(&r, m.nt, "plane");
      CHECKF(r.memory_bytes > prev, "plane %d: %zu bytes, smaller plane %zu", n, r.memory_bytes, prev);
      prev = r.memory_bytes;
      /* A flat scene needs no more than a cell or two across its (zero) thickness. */
      CHECKF(r.grid_resolution[0] > 0 && r.grid_resolution[1] > 0 && r.grid_resolution[2] > 0,
             "plane %d: resolution %u x %u x %u", n, (unsigned)r.grid_resolution[0], (unsigned)r.grid_resolution[1],
             (unsigned)r.grid_resolution[2]);
      CHECKF(r.grid_resolution[2] <= 2, "plane %d: %u cells across a flat scene", n, (unsigned)r.grid_resolution[2]);
      rq_scene_free(scene);
    }
    mesh_free(&m);
  }
}

static void test_auto_report(void) {
  test_mesh m = mesh_soup(3, 500);
  rq_mesh_desc d = mesh_desc(&m);
  const uint64_t budgets[] = {0, 1, 1000, 1000000, 10000000000ull};
  for (size_t i = 0; i < sizeof budgets / sizeof budgets[0]; i++) {
    rq_build_options o;
    rq_build_options_init(&o);
    o.expected_rays = budgets[i];
    rq_scene *scene = NULL;
    CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
    if (!scene) {
      continue;
    }
    rq_scene_report r = test_report(scene);
    check_common(&r, m.nt, "auto");
    CHECKF(r.expected_rays == budgets[i], "budget %llu: report says %llu", (unsigned long long)budgets[i],
           (unsigned long long)r.expected_rays);
    if (budgets[i] == 0) {
      /* Unknown budget: start on the grid and say so. */
      CHECK(r.structure == RQ_STRUCTURE_GRID);
      CHECKF(r.outcome == RQ_OUTCOME_ONLINE_ON_GRID, "unknown budget: outcome %u", (unsigned)r.outcome);
    } else {
      CHECKF(r.outcome != RQ_OUTCOME_ONLINE_ON_GRID && r.outcome != RQ_OUTCOME_ONLINE_SWITCHED,
             "budget %llu: online outcome %u", (unsigned long long)budgets[i], (unsigned)r.outcome);
    }
    if (r.structure == RQ_STRUCTURE_GRID) {
      CHECK(r.grid_resolution[0] > 0 && r.grid_resolution[1] > 0 && r.grid_resolution[2] > 0);
    }
    CHECK(r.memory_bytes > 0);
    /* rq_scene_update between batches keeps the report coherent. */
    CHECK_STATUS(rq_scene_update(scene, 5000, 0), RQ_STATUS_OK);
    CHECK_STATUS(rq_scene_update(scene, 100000, 100000), RQ_STATUS_OK);
    rq_scene_report after = test_report(scene);
    check_common(&after, m.nt, "auto after update");
    if (after.structure == RQ_STRUCTURE_GRID) {
      CHECK(after.grid_resolution[0] > 0);
    }
    rq_scene_free(scene);
  }
  /* The same through NULL options. */
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  if (scene) {
    rq_scene_report r = test_report(scene);
    check_common(&r, m.nt, "defaults");
    CHECK(r.expected_rays == 0);
    CHECK(r.structure == RQ_STRUCTURE_GRID && r.outcome == RQ_OUTCOME_ONLINE_ON_GRID);
    rq_scene_free(scene);
  }
  mesh_free(&m);
}

static void test_kdtree_report(void) {
  test_mesh m = mesh_cube(3);
  rq_mesh_desc d = mesh_desc(&m);
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = RQ_STRUCTURE_KDTREE;
  rq_scene *scene = NULL;
  rq_status s = rq_scene_build(&d, &o, NULL, &scene);
  CHECKF(s == RQ_STATUS_OK, "kdtree: %u (%s)", (unsigned)s, rq_status_str(s));
  if (scene) {
    rq_scene_report r = test_report(scene);
    check_common(&r, m.nt, "kdtree");
    CHECK(r.structure == RQ_STRUCTURE_KDTREE && r.outcome == RQ_OUTCOME_FORCED);
    CHECK(r.memory_bytes > 0);
    /* The tree's shape: at least a root, no grid, every triangle referenced at least once. */
    CHECKF(r.kd_node_count >= 1 && r.kd_node_count % 2 == 1, "kd_node_count %zu", r.kd_node_count);
    CHECKF(r.kd_depth <= 60, "kd_depth %u", (unsigned)r.kd_depth);
    CHECK(r.grid_resolution[0] == 0 && r.grid_resolution[1] == 0 && r.grid_resolution[2] == 0);
    CHECKF(r.references_per_triangle >= 1.0, "references_per_triangle %g", r.references_per_triangle);
    rq_scene_free(scene);
  }
  mesh_free(&m);
}

static void test_edge_meshes(void) {
  /* Empty: nothing held for triangles, no grid cells needed. */
  rq_mesh_desc d = {NULL, 0, 12, NULL, 0};
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  if (scene) {
    rq_scene_report r = test_report(scene);
    check_common(&r, 0, "empty");
    CHECK(r.references_per_triangle == 0.0 || isnan(r.references_per_triangle));
    rq_scene_free(scene);
  }
  /* Degenerate only: counted as triangles, nothing referenced. */
  const float v[] = {0, 0, 0, 1, 0, 0, 2, 0, 0};
  const uint32_t idx[] = {0, 1, 2, 0, 0, 1, 2, 2, 2};
  rq_mesh_desc dd = {v, 3, 12, idx, 3};
  scene = NULL;
  CHECK_STATUS(rq_scene_build(&dd, NULL, NULL, &scene), RQ_STATUS_OK);
  if (scene) {
    rq_scene_report r = test_report(scene);
    check_common(&r, 3, "degenerate");
    CHECK(r.references_per_triangle == 0.0 || isnan(r.references_per_triangle));
    rq_scene_free(scene);
  }
  /* One triangle: a non-empty mesh has a grid of at least one cell. */
  test_mesh one;
  memset(&one, 0, sizeof one);
  mesh_triangle(&one, mesh_vertex(&one, 0, 0, 0), mesh_vertex(&one, 1, 0, 0), mesh_vertex(&one, 0, 1, 0));
  scene = test_build(&one, RQ_STRUCTURE_GRID);
  if (scene) {
    rq_scene_report r = test_report(scene);
    check_common(&r, 1, "one triangle");
    CHECK(r.grid_resolution[0] >= 1 && r.grid_resolution[1] >= 1 && r.grid_resolution[2] >= 1);
    CHECK(r.memory_bytes >= 3 * 12);
    CHECK(r.references_per_triangle >= 1.0);
    rq_scene_free(scene);
  }
  mesh_free(&one);
}

int main(void) {
  test_grid_report();
  test_auto_report();
  test_kdtree_report();
  test_edge_meshes();
  return test_finish("report");
}
