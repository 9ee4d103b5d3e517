/* precision.c: closed cubes far from the origin, tiny, huge, and with a distant twin. Rays from inside
 * a closed convex mesh must hit it, and exactly where they leave it: whichever triangle the hit is
 * reported on, its t is the ray's exit from the cube (computed here in double from the same float
 * ray and the same float face coordinates) up to the rounding of t to float. Meshes far from the
 * origin are where a tolerance measured in absolute coordinates, or a t taken from anything but the
 * ray's crossing of the triangle's plane, shows. */
#include "common.h"

#include <float.h>

static void test_moved_cubes(int structure) {
  const struct {
    double scale, offset;
    int twin;
  } cases[] = {{1.0, 0.0, 1}, {1e-2, 1000.0, 0}, {1e4, -3e5, 0}, {1.0, 1e5, 0}, {1e-4, 0.0, 0}, {1e6, 0.0, 1}};
  /* Not {1e-3, 1000}: float spacing at 1000 (6.1e-5) is an eighth of that cube's triangle legs, so its
   * origins and vertices are quantized beyond what any float tracer can answer exactly (docs/design.md). */
  for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
    const double scale = cases[c].scale, offset = cases[c].offset;
    test_mesh m = mesh_cube(4);
    size_t nv = m.nv, nt = m.nt;
    if (cases[c].twin) {
      /* A copy of the cube 10^4 sizes away along x: a long, sparse grid. */
      for (size_t i = 0; i < nv; i++) {
        mesh_vertex(&m, m.v[3 * i] + 1e4f, m.v[3 * i + 1], m.v[3 * i + 2]);
      }
      for (size_t t = 0; t < nt; t++) {
        mesh_triangle(&m, m.idx[3 * t] + (uint32_t)nv, m.idx[3 * t + 1] + (uint32_t)nv, m.idx[3 * t + 2] + (uint32_t)nv);
      }
    }
    for (size_t i = 0; i < 3 * m.nv; i++) {
      m.v[i] = (float)(offset + scale * (double)m.v[i]);
    }
    rq_scene *scene = test_build(&m, structure);
    if (!scene) {
      mesh_free(&m);
      continue;
    }
    uint64_t rng = 99 + c;
    long leaks = 0;
    for (int i = 0; i < 2000; i++) {
      double shift = (cases[c].twin && (i & 1)) ? 1e4 : 0.0;
      double o[3];
      float dir[3];
      for (int k = 0; k < 3; k++) {
        o[k] = rng_float(&rng, -0.95f, 0.95f);
      }
      o[0] += shift;
      if (i % 3 == 0) {
        /* Towards a lattice point of the surface (vertex or edge midpoint, in cube units). */
        int l[3];
        for (int k = 0; k < 3; k++) {
          l[k] = (int)(rng_next(&rng) % 9);
        }
        l[rng_next(&rng) % 3] = (rng_next(&rng) & 1) ? 8 : 0;
        for (int k = 0; k < 3; k++) {
          dir[k] = (float)((-1.0 + 0.25 * l[k] + (k == 0 ? shift : 0.0) - o[k]) * scale);
        }
      } else if (i % 3 == 1) {
        dir[0] = dir[1] = dir[2] = 0.0f;
        dir[i % 3] = (rng_next(&rng) & 1) ? 1.0f : -1.0f;
      } else {
        rng_dir(&rng, dir);
      }
      rq_ray r = make_ray((float)(offset + scale * o[0]), (float)(offset + scale * o[1]), (float)(offset + scale * o[2]),
                          dir[0], dir[1], dir[2]);
      rq_hit h = trace(scene, &r);
      if (h.prim == RQ_INVALID_ID) {
        leaks++;
        CHECKF(0, "scale %g offset %g: ray %d leaked: org (%a, %a, %a) dir (%a, %a, %a)", scale, offset, i,
               (double)r.org[0], (double)r.org[1], (double)r.org[2], (double)r.dir[0], (double)r.dir[1],
               (double)r.dir[2]);
        continue;
      }
      /* The faces of the moved cube, as rounded to float in the mesh. */
      double lo[3], hi[3];
      for (int k = 0; k < 3; k++) {
        lo[k] = (float)(offset + scale * ((k == 0 ? shift : 0.0) - 1.0));
        hi[k] = (float)(offset + scale * ((k == 0 ? shift : 0.0) + 1.0));
      }
      char label[64];
      snprintf(label, sizeof label, "scale %g offset %g%s", scale, offset, shift != 0.0 ? " (the twin)" : "");
      CHECK_EXIT(r, h, lo, hi, label, i);
      CHECKF(h.prim < (shift != 0.0 ? 2 * nt : nt) && h.prim >= (shift != 0.0 ? nt : 0),
             "scale %g offset %g: ray %d hit the other cube (prim %u)", scale, offset, i, (unsigned)h.prim);
    }
    CHECKF(leaks == 0, "scale %g offset %g: %ld rays leaked", scale, offset, leaks);
    rq_scene_free(scene);
    mesh_free(&m);
  }
}

int main(void) {
  const int structures[] = {RQ_STRUCTURE_GRID, RQ_STRUCTURE_AUTO, -1};
  const char *names[] = {"grid", "auto", "defaults"};
  for (int i = 0; i < 3; i++) {
    long before = test_failures;
    test_moved_cubes(structures[i]);
    printf("precision with %s: %ld failures\n", names[i], test_failures - before);
  }
  /* The kd-tree, when this build has one. */
  test_mesh m = mesh_cube(1);
  rq_mesh_desc d = mesh_desc(&m);
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = RQ_STRUCTURE_KDTREE;
  rq_scene *scene = NULL;
  rq_status st = rq_scene_build(&d, &o, NULL, &scene);
  CHECKF(st == RQ_STATUS_OK, "kdtree: %u (%s)", (unsigned)st, rq_status_str(st));
  if (scene) {
    rq_scene_free(scene);
    long before = test_failures;
    test_moved_cubes(RQ_STRUCTURE_KDTREE);
    printf("precision with kdtree: %ld failures\n", test_failures - before);
  }
  mesh_free(&m);
  return test_finish("precision");
}
