/* clock.c: rq_build_options.clock. rq_build_options_init sets the library's own clock (this build has
 * std); with the caller's sample rays, AUTO's check after a kd-tree build reads the clock twice around
 * each of its two timed passes over them (the grid's, then the kd-tree's) and keeps the kd-tree only
 * if the clock says it took less time; NULL prices their counted work instead, and so are the
 * library's own samples, whatever the clock; a caller whose struct_size stops before `clock` gets no
 * clock (its own is never called). */
#include "common.h"

#include <math.h>
#include <stddef.h>

/* A scripted clock: its n-th reading (from 1) is n*n when `slower_later` (so the later pass, the
 * kd-tree's, takes longer), else 1000n - n*n (it takes less). */
typedef struct {
  uint64_t readings;
  int slower_later;
} script;

static uint64_t scripted(void *user) {
  script *s = (script *)user;
  uint64_t n = ++s->readings;
  return s->slower_later ? n * n : 1000 * n - n * n;
}

/* Estimates that always favour the kd-tree (a grid ray 1 µs, a kd-tree ray 1 ns, a build almost free),
 * and a check whose prices let the Sierpinski tetrahedron's kd-tree pass (see memory_monitor.c). */
static rq_calibration *favouring_the_kd_tree(void) {
  static const double values[8] = {10.0, 1000.0, 100.0, 1.0, 0.001, 1.0, 0.0, 1.0};
  return test_calibration(values);
}

/* Rays along +z through a 24 x 24 lattice over the mesh's x-y bounds, from below it. */
#define SAMPLES (24 * 24)
static rq_ray samples[SAMPLES];

static void make_samples(const test_mesh *m) {
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t i = 0; i < m->nv; i++) {
    for (int a = 0; a < 3; a++) {
      lo[a] = m->v[3 * i + a] < lo[a] ? m->v[3 * i + a] : lo[a];
      hi[a] = m->v[3 * i + a] > hi[a] ? m->v[3 * i + a] : hi[a];
    }
  }
  for (int j = 0; j < 24; j++) {
    for (int i = 0; i < 24; i++) {
      float x = lo[0] + (hi[0] - lo[0]) * ((float)i + 0.5f) / 24.0f;
      float y = lo[1] + (hi[1] - lo[1]) * ((float)j + 0.5f) / 24.0f;
      samples[24 * j + i] = make_ray(x, y, lo[2] - 1.0f, 0.05f, 0.03f, 1.0f);
    }
  }
}

/* AUTO with a huge budget; `own`: the library's sample rays, else `samples`. */
static rq_scene_report built(const rq_mesh_desc *d, const rq_calibration *calib, rq_clock_fn clock, void *user,
                             uint32_t struct_size, int own) {
  rq_build_options o;
  rq_build_options_init(&o);
  o.expected_rays = 1000000000000ull;
  o.clock = clock;
  o.clock_user = user;
  if (!own) {
    o.sample_rays = samples;
    o.sample_ray_count = SAMPLES;
  }
  o.struct_size = struct_size;
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(d, &o, calib, &scene), RQ_STATUS_OK);
  rq_scene_report r;
  memset(&r, 0, sizeof r);
  if (scene) {
    r = test_report(scene);
    rq_scene_free(scene);
  }
  return r;
}

int main(void) {
  rq_build_options o;
  rq_build_options_init(&o);
  CHECK(o.clock != NULL && o.clock_user == NULL);
  if (o.clock) {
    uint64_t a = o.clock(NULL);
    CHECK(o.clock(NULL) >= a);
  }

  test_mesh mesh = mesh_tetra(5);
  rq_mesh_desc d = mesh_desc(&mesh);
  make_samples(&mesh);
  rq_calibration *calib = favouring_the_kd_tree();
  const uint32_t full = (uint32_t)sizeof(rq_build_options);

  script slower = {0, 1};
  rq_scene_report r = built(&d, calib, scripted, &slower, full, 0);
  CHECKF(slower.readings == 4, "%llu readings", (unsigned long long)slower.readings);
  CHECK(r.structure == RQ_STRUCTURE_GRID && r.outcome == RQ_OUTCOME_GRID_FASTER_PER_RAY);

  script faster = {0, 0};
  r = built(&d, calib, scripted, &faster, full, 0);
  CHECKF(faster.readings == 4, "%llu readings", (unsigned long long)faster.readings);
  CHECK(r.structure == RQ_STRUCTURE_KDTREE && r.outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN);

  /* The library's own samples: priced (the tetrahedron's kd-tree passes), the clock not read. */
  script unread = {0, 1};
  r = built(&d, calib, scripted, &unread, full, 1);
  CHECK(unread.readings == 0);
  CHECK(r.structure == RQ_STRUCTURE_KDTREE && r.outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN);

  /* No clock: the counted work of the caller's samples decides, the same way every time. */
  rq_scene_report priced = built(&d, calib, NULL, NULL, full, 0);
  r = built(&d, calib, NULL, NULL, full, 0);
  CHECK(r.structure == priced.structure && r.outcome == priced.outcome);
  CHECK(priced.outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN || priced.outcome == RQ_OUTCOME_GRID_FASTER_PER_RAY);

  /* An older caller's struct_size, which stops before `clock`: no clock (as before the field
   * existed), so the script is never read and the counted work decides. */
  script old = {0, 1};
  r = built(&d, calib, scripted, &old, (uint32_t)offsetof(rq_build_options, clock), 0);
  CHECK(old.readings == 0);
  CHECK(r.structure == priced.structure && r.outcome == priced.outcome);

  rq_calibration_free(calib);
  mesh_free(&mesh);
  return test_finish("clock");
}
