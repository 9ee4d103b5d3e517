/* memory_monitor.c: rq_build_options.memory_monitor is asked before every allocation of a build, in
 * every mode (GRID, KDTREE, AUTO with the switch to the kd-tree, and the switch in rq_scene_update);
 * a refusal at any of those points fails the call with RQ_STATUS_CANCELLED, tells on_error, leaves
 * *out alone and leaks nothing (AddressSanitizer's leak check runs at exit). Also: a caller whose
 * struct_size stops before the new fields is not asked, and in this (std) build rq_set_allocator and
 * rq_set_panic_hook are RQ_STATUS_UNSUPPORTED. */
#include "common.h"

#include <stddef.h>

/* A monitor that counts the calls, remembers the largest total it was told, and refuses call number
 * `refuse_at` (1-based; 0 = never) or every call while `refuse_all` is set. */
typedef struct monitor {
  size_t calls;
  size_t largest;
  size_t refuse_at;
  int refuse_all;
  size_t refused;
} monitor;

static bool monitor_fn(void *user, size_t bytes) {
  monitor *m = (monitor *)user;
  m->calls++;
  if (bytes > m->largest) {
    m->largest = bytes;
  }
  if (m->refuse_all || m->calls == m->refuse_at) {
    m->refused++;
    return false;
  }
  return true;
}

typedef struct errors {
  unsigned count;
  rq_status last;
} errors;

static void on_error(void *user, rq_status status, const char *message) {
  errors *e = (errors *)user;
  (void)message;
  e->count++;
  e->last = status;
}

static rq_build_options options(rq_structure structure, uint64_t expected_rays, monitor *m, errors *e) {
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = structure;
  o.expected_rays = expected_rays;
  o.memory_monitor = monitor_fn;
  o.memory_monitor_user = m;
  o.on_error = on_error;
  o.user = e;
  /* The check after a kd-tree build priced from counted work (deterministic), not timed. */
  o.clock = NULL;
  return o;
}

/* A calibration whose estimates always favour the kd-tree (the grid costs 1 µs a ray, the kd-tree 1 ns
 * and almost nothing to build) and whose check prices grid cells far above triangle tests (the
 * check prices a kd-tree node at a twentieth of a cell, so the kd-tree passes on the Sierpinski
 * tetrahedron: 13 nodes and 36 tests a sample ray against the grid's 7 cells and 50 tests). Free
 * with rq_calibration_free. */
static rq_calibration *calibration_favouring_the_kd_tree(void) {
  static const double values[8] = {10.0, 1000.0, 100.0, 1.0, 0.001, 1.0, 0.0, 1.0};
  return test_calibration(values);
}

/* Builds with a monitor that allows everything and returns how many times it was asked. `want` is the
 * structure the scene must end on; RQ_STRUCTURE_AUTO accepts either. `calib` NULL: the built-in. */
static size_t calls_of_full_build(const rq_mesh_desc *d, rq_structure structure, uint64_t rays,
                                  const rq_calibration *calib, rq_structure want, const char *what) {
  monitor m;
  errors e;
  memset(&m, 0, sizeof m);
  memset(&e, 0, sizeof e);
  rq_build_options o = options(structure, rays, &m, &e);
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(d, &o, calib, &scene), RQ_STATUS_OK);
  if (!scene) {
    return 0;
  }
  rq_scene_report r = test_report(scene);
  CHECKF(want == RQ_STRUCTURE_AUTO || r.structure == want, "%s: structure %u", what, (unsigned)r.structure);
  CHECKF(m.calls > 0, "%s: the monitor was never asked", what);
  /* The totals it is told cover what the scene keeps. */
  CHECKF(m.largest >= r.memory_bytes, "%s: largest total told %zu < scene memory %zu", what, m.largest,
         r.memory_bytes);
  CHECK(e.count == 0);
  rq_scene_free(scene);
  return m.calls;
}

/* Refusing call k, for every k the full build makes from `from` on, cancels the build. */
static void refuse_each(const rq_mesh_desc *d, rq_structure structure, uint64_t rays,
                        const rq_calibration *calib, size_t from, size_t calls, const char *what) {
  for (size_t k = from; k <= calls; k++) {
    monitor m;
    errors e;
    memset(&m, 0, sizeof m);
    memset(&e, 0, sizeof e);
    m.refuse_at = k;
    rq_build_options o = options(structure, rays, &m, &e);
    rq_scene *scene = (rq_scene *)test_sentinel();
    rq_status s = rq_scene_build(d, &o, calib, &scene);
    CHECKF(s == RQ_STATUS_CANCELLED, "%s: refusing call %zu of %zu gave %u (%s)", what, k, calls, (unsigned)s,
           rq_status_str(s));
    CHECKF(scene == (rq_scene *)test_sentinel(), "%s: refusing call %zu wrote *out", what, k);
    CHECKF(m.calls == k && m.refused == 1, "%s: asked %zu times after refusing call %zu", what, m.calls, k);
    CHECKF(e.count == 1 && e.last == RQ_STATUS_CANCELLED, "%s: on_error told %u times, last %u", what, e.count,
           (unsigned)e.last);
    if (s == RQ_STATUS_OK) {
      rq_scene_free(scene);
    }
  }
}

static void each_mode(void) {
  test_mesh m = mesh_soup(7, 400);
  rq_mesh_desc d = mesh_desc(&m);

  size_t grid = calls_of_full_build(&d, RQ_STRUCTURE_GRID, 0, NULL, RQ_STRUCTURE_GRID, "grid");
  refuse_each(&d, RQ_STRUCTURE_GRID, 0, NULL, 1, grid, "grid");

  size_t kd = calls_of_full_build(&d, RQ_STRUCTURE_KDTREE, 0, NULL, RQ_STRUCTURE_KDTREE, "kd-tree");
  refuse_each(&d, RQ_STRUCTURE_KDTREE, 0, NULL, 1, kd, "kd-tree");

  /* AUTO with a huge budget and a calibration that favours the kd-tree builds the grid, decides for
   * the kd-tree and builds it (and, where the kd-tree saves no work on the sample rays, as it may on a
   * soup, builds the grid again): it asks more often than the grid alone, and refusing any call
   * cancels the build. */
  const uint64_t huge = 1000000000000ull;
  rq_calibration *favour_kd = calibration_favouring_the_kd_tree();
  size_t autokd = calls_of_full_build(&d, RQ_STRUCTURE_AUTO, huge, favour_kd, RQ_STRUCTURE_AUTO, "auto");
  CHECKF(autokd > grid, "auto asked %zu times, the grid alone %zu", autokd, grid);
  refuse_each(&d, RQ_STRUCTURE_AUTO, huge, favour_kd, 1, autokd, "auto");
  rq_calibration_free(favour_kd);
  mesh_free(&m);
}

/* The switch inside rq_scene_update asks the monitor the scene was built with. */
static void update_switch(void) {
  /* A Sierpinski tetrahedron: a kd-tree saves work on it, so the switch keeps the kd-tree (on a soup
   * the check after the build could keep the grid instead). */
  test_mesh mesh = mesh_tetra(5);
  rq_mesh_desc d = mesh_desc(&mesh);
  monitor m;
  errors e;
  memset(&m, 0, sizeof m);
  memset(&e, 0, sizeof e);
  rq_build_options o = options(RQ_STRUCTURE_AUTO, 0, &m, &e);
  rq_calibration *calib = calibration_favouring_the_kd_tree();
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, calib, &scene), RQ_STATUS_OK);
  rq_calibration_free(calib);
  if (!scene) {
    mesh_free(&mesh);
    return;
  }
  rq_scene_report before = test_report(scene);
  CHECK(before.structure == RQ_STRUCTURE_GRID && before.outcome == RQ_OUTCOME_ONLINE_ON_GRID);
  rq_ray ray = make_ray(0.1f, 0.2f, -5.0f, 0.01f, 0.02f, 1.0f);
  rq_hit h0 = trace(scene, &ray);

  m.refuse_all = 1;
  size_t calls = m.calls;
  CHECK_STATUS(rq_scene_update(scene, 1000000000000ull, 1000000000000ull), RQ_STATUS_CANCELLED);
  CHECKF(m.calls > calls, "the update did not ask the monitor (%zu calls)", m.calls);
  rq_scene_report refused = test_report(scene);
  CHECK(refused.structure == RQ_STRUCTURE_GRID && refused.outcome == RQ_OUTCOME_ONLINE_ON_GRID);
  CHECK(refused.memory_bytes == before.memory_bytes);
  rq_hit h1 = trace(scene, &ray);
  CHECK(same_hit(&h0, &h1));

  m.refuse_all = 0;
  CHECK_STATUS(rq_scene_update(scene, 1000000000000ull, 1000000000000ull), RQ_STATUS_OK);
  rq_scene_report after = test_report(scene);
  CHECK(after.structure == RQ_STRUCTURE_KDTREE && after.outcome == RQ_OUTCOME_ONLINE_SWITCHED);
  rq_hit h2 = trace(scene, &ray);
  CHECK(same_hit(&h0, &h2));
  rq_scene_free(scene);
  mesh_free(&mesh);
}

/* A caller built against the header before the monitor existed: struct_size stops before it, so
 * whatever lies in those bytes is never called. */
static void old_struct_size(void) {
  test_mesh mesh = mesh_cube(4);
  rq_mesh_desc d = mesh_desc(&mesh);
  monitor m;
  errors e;
  memset(&m, 0, sizeof m);
  memset(&e, 0, sizeof e);
  m.refuse_all = 1;
  rq_build_options o = options(RQ_STRUCTURE_GRID, 0, &m, &e);
  o.struct_size = (uint32_t)offsetof(rq_build_options, memory_monitor);
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
  CHECK(m.calls == 0);
  rq_scene_free(scene);

  /* Covered, the same options are refused. */
  o.struct_size = (uint32_t)sizeof o;
  scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_CANCELLED);
  CHECK(scene == NULL && m.calls == 1);
  /* The defaults have no monitor. */
  rq_build_options_init(&o);
  CHECK(o.memory_monitor == NULL && o.memory_monitor_user == NULL);
  mesh_free(&mesh);
}

static void hooks_unsupported_here(void) {
  CHECK_STATUS(rq_set_allocator(NULL), RQ_STATUS_UNSUPPORTED);
  CHECK_STATUS(rq_set_panic_hook(NULL, NULL), RQ_STATUS_UNSUPPORTED);
  CHECK(strcmp(rq_status_str(RQ_STATUS_CANCELLED), "cancelled") == 0);
}

int main(void) {
  each_mode();
  update_switch();
  old_struct_size();
  hooks_unsupported_here();
  return test_finish("memory_monitor");
}
