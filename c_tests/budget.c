/* budget.c: what rq_build_options.expected_rays means and how rq_scene_update ends. An AT_MOST bound
 * below the estimated break-even W* keeps the grid for good; one above starts on the grid and switches
 * once the rays traced reach W* while at least W* may still come; RQ_RAYS_REMAINING_NONE ends the
 * online rule; a budget_kind outside the enum is refused; a caller whose struct_size stops before
 * budget_kind gets EXPECTED. */
#include "common.h"

#include <stddef.h>

/* The grid costs 1 µs a ray plus its counted work (cells priced far above tests, so the kd-tree,
 * whose nodes the check prices at a twentieth of a cell, passes the check after its build on the
 * Sierpinski tetrahedron: 13 nodes and 36 tests a sample ray against the grid's 7 cells and 50
 * tests),
 * the kd-tree 1 ns a ray and 100 µs per N log2 N to build: W* on that mesh is ~10⁶, above the budgets
 * from which the library makes its full set of sample rays, so every bound sees the same estimate (an
 * unknown budget samples fewer: the probe's budget is the largest). */
static rq_calibration *dear_build(void) {
  static const double values[8] = {10.0, 1000.0, 100.0, 1.0, 100000.0, 1.0, 0.0, 1.0};
  return test_calibration(values);
}

static rq_scene *build(const rq_mesh_desc *d, const rq_calibration *calib, uint64_t rays, rq_budget_kind kind) {
  rq_build_options o;
  rq_build_options_init(&o);
  CHECK(o.budget_kind == RQ_BUDGET_EXPECTED);
  o.expected_rays = rays;
  o.budget_kind = kind;
  /* The check after a kd-tree build priced from counted work (deterministic), not timed. */
  o.clock = NULL;
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(d, &o, calib, &scene), RQ_STATUS_OK);
  return scene;
}

static int on(const rq_scene *scene, rq_structure structure, rq_outcome outcome) {
  rq_scene_report r = test_report(scene);
  return r.structure == structure && r.outcome == outcome;
}

int main(void) {
  test_mesh mesh = mesh_tetra(5);
  rq_mesh_desc d = mesh_desc(&mesh);
  rq_calibration *calib = dear_build();
  rq_scene *probe = build(&d, calib, UINT64_MAX, RQ_BUDGET_EXPECTED);
  if (!calib || !probe) {
    return test_finish("budget");
  }
  double w = test_report(probe).break_even_rays;
  rq_scene_free(probe);
  CHECKF(w > 4.0 * 128 * 24 * 24 && w < 1e12, "W* = %g", w);
  uint64_t due = (uint64_t)ceil(w);

  /* Below W*: the grid for good, even if the caller then traces more than it said. */
  rq_scene *s = build(&d, calib, due / 2, RQ_BUDGET_AT_MOST);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_BELOW_BREAK_EVEN));
  CHECK_STATUS(rq_scene_update(s, 2 * due, 0), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_BELOW_BREAK_EVEN));
  rq_scene_free(s);

  /* The same count as EXPECTED builds the kd-tree at once when it is above W*. */
  s = build(&d, calib, 2 * due, RQ_BUDGET_EXPECTED);
  CHECK(on(s, RQ_STRUCTURE_KDTREE, RQ_OUTCOME_ABOVE_BREAK_EVEN));
  rq_scene_free(s);

  /* At most 2·W*: on the grid until W* rays are traced, then the kd-tree. */
  s = build(&d, calib, 2 * due, RQ_BUDGET_AT_MOST);
  rq_ray ray = make_ray(0.1f, 0.2f, -5.0f, 0.01f, 0.02f, 1.0f);
  rq_hit h0 = trace(s, &ray);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  CHECK_STATUS(rq_scene_update(s, due - 1, 0), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  CHECK_STATUS(rq_scene_update(s, 1, 0), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_KDTREE, RQ_OUTCOME_ONLINE_SWITCHED));
  rq_hit h1 = trace(s, &ray);
  CHECK(same_hit(&h0, &h1));
  rq_scene_free(s);

  /* At most 1.5·W*: when W* are traced fewer than W* may come, and the switch could not pay. */
  s = build(&d, calib, due + due / 2, RQ_BUDGET_AT_MOST);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  CHECK_STATUS(rq_scene_update(s, due, 0), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  rq_scene_free(s);

  /* Unknown budget, last batch told: past W* but nothing more to come, so no switch, ever. */
  s = build(&d, calib, 0, RQ_BUDGET_EXPECTED);
  CHECK_STATUS(rq_scene_update(s, due + 1, RQ_RAYS_REMAINING_NONE), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  CHECK_STATUS(rq_scene_update(s, 10 * due, 0), RQ_STATUS_OK);
  CHECK(on(s, RQ_STRUCTURE_GRID, RQ_OUTCOME_ONLINE_ON_GRID));
  rq_scene_free(s);

  /* A budget_kind outside the enum is refused; a struct_size before budget_kind reads EXPECTED. */
  rq_build_options o;
  rq_build_options_init(&o);
  o.expected_rays = 2 * due;
  uint32_t bad = 7;
  memcpy((unsigned char *)&o + offsetof(rq_build_options, budget_kind), &bad, sizeof bad);
  rq_scene *refused = (rq_scene *)test_sentinel();
  CHECK_STATUS(rq_scene_build(&d, &o, calib, &refused), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(refused == (rq_scene *)test_sentinel());
  o.struct_size = (uint32_t)offsetof(rq_build_options, budget_kind);
  s = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, calib, &s), RQ_STATUS_OK);
  CHECK(s && on(s, RQ_STRUCTURE_KDTREE, RQ_OUTCOME_ABOVE_BREAK_EVEN));
  rq_scene_free(s);

  rq_calibration_free(calib);
  mesh_free(&mesh);
  return test_finish("budget");
}
