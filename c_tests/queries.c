/* queries.c: the query contract (DESIGN §3) through the C ABI, on procedural meshes: the [tmin, tmax]
 * window, the exact miss, barycentrics, NaN and zero directions, axis-parallel and -0.0 directions,
 * closed meshes that never leak, ties to the lowest id, occluded == intersect, intersect_n == single
 * calls, an independent double-precision reference, and agreement between structures. Every test runs
 * for the grid, for AUTO, and for the default (NULL) options; the kd-tree is compared bit for bit
 * with the grid when this build has one. */
#include "common.h"

#include <float.h>

/* Structures to run: -1 means NULL options (the defaults). */
static const int structures[] = {RQ_STRUCTURE_GRID, RQ_STRUCTURE_AUTO, -1};
static const char *structure_name(int s) {
  return s == RQ_STRUCTURE_GRID ? "grid" : s == RQ_STRUCTURE_AUTO ? "auto" : s == RQ_STRUCTURE_KDTREE ? "kdtree" : "defaults";
}

static rq_ray window(rq_ray r, float tmin, float tmax) {
  r.tmin = tmin;
  r.tmax = tmax;
  return r;
}


/* ---- the t window ------------------------------------------------------------------------------ */

static void test_window(int structure) {
  /* A 16 x 16 plane at z = 0 (many grid cells) and, for the ordering checks, a second surface: two
   * big triangles at z = 1 over the same square. */
  test_mesh m = mesh_plane(16);
  uint32_t a = mesh_vertex(&m, 0, 0, 1), b = mesh_vertex(&m, 16, 0, 1), c = mesh_vertex(&m, 16, 16, 1),
           d = mesh_vertex(&m, 0, 16, 1);
  const uint32_t top0 = mesh_triangle(&m, a, b, c), top1 = mesh_triangle(&m, a, c, d);
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  uint64_t rng = 1234;
  for (int i = 0; i < 300; i++) {
    /* Start between the surfaces, pointing down at the plane (oblique). */
    float x = rng_float(&rng, 2, 14), y = rng_float(&rng, 2, 14);
    rq_ray r = make_ray(x, y, 0.5f, rng_float(&rng, -0.5f, 0.5f), rng_float(&rng, -0.5f, 0.5f),
                        -rng_float(&rng, 0.25f, 2.0f));
    rq_hit h0 = trace(scene, &r);
    CHECKF(h0.prim != RQ_INVALID_ID && h0.prim < top0, "ray %d: prim %u", i, (unsigned)h0.prim);
    if (h0.prim == RQ_INVALID_ID) {
      continue;
    }
    float t0 = h0.t;
    CHECK(t0 > 0.0f);
    rq_hit h;
    /* The hit's own t as either end of the window (and as both) is accepted, bit for bit the same. */
    h = trace(scene, (rq_ray[]){window(r, t0, INFINITY)});
    CHECKF(same_hit(&h, &h0), "ray %d: tmin = t", i);
    h = trace(scene, (rq_ray[]){window(r, 0.0f, t0)});
    CHECKF(same_hit(&h, &h0), "ray %d: tmax = t", i);
    h = trace(scene, (rq_ray[]){window(r, t0, t0)});
    CHECKF(same_hit(&h, &h0), "ray %d: tmin = tmax = t", i);
    h = trace(scene, (rq_ray[]){window(r, -INFINITY, INFINITY)});
    CHECKF(h.prim == h0.prim || (h.prim == top0 || h.prim == top1), "ray %d: [-inf, inf] prim %u", i,
           (unsigned)h.prim);
    /* One ulp outside: rejected (nothing else lies below the plane). */
    h = trace(scene, (rq_ray[]){window(r, nextafterf(t0, INFINITY), INFINITY)});
    CHECKF(h.prim == RQ_INVALID_ID, "ray %d: tmin one ulp past t still hit prim %u", i, (unsigned)h.prim);
    h = trace(scene, (rq_ray[]){window(r, 0.0f, nextafterf(t0, 0.0f))});
    CHECKF(h.prim == RQ_INVALID_ID, "ray %d: tmax one ulp before t still hit prim %u", i, (unsigned)h.prim);
    h = trace(scene, (rq_ray[]){window(r, t0, nextafterf(t0, 0.0f))});
    CHECKF(h.prim == RQ_INVALID_ID, "ray %d: tmin > tmax by one ulp", i);
    /* tmin > tmax misses, however the window straddles the hit. */
    h = trace(scene, (rq_ray[]){window(r, t0 + 1.0f, t0 - 0.25f)});
    CHECK(h.prim == RQ_INVALID_ID);
    h = trace(scene, (rq_ray[]){window(r, INFINITY, 0.0f)});
    CHECK(h.prim == RQ_INVALID_ID);
    /* An empty window far away. */
    h = trace(scene, (rq_ray[]){window(r, INFINITY, INFINITY)});
    CHECK(h.prim == RQ_INVALID_ID);
    /* A window entirely before the origin sees the top surface behind (t < 0) but not the plane. */
    h = trace(scene, (rq_ray[]){window(r, -INFINITY, 0.0f)});
    CHECKF(h.prim == top0 || h.prim == top1, "ray %d: [-inf, 0] prim %u", i, (unsigned)h.prim);
    CHECK(h.t < 0.0f);
    /* With both surfaces in the window, the smallest t (the top one, behind) is the closest. */
    h = trace(scene, (rq_ray[]){window(r, -100.0f, 100.0f)});
    CHECKF((h.prim == top0 || h.prim == top1) && h.t < 0.0f, "ray %d: [-100, 100] prim %u t %g", i,
           (unsigned)h.prim, (double)h.t);
  }
  /* From above both surfaces: the top one first; starting the window past it reaches the plane. */
  for (int i = 0; i < 100; i++) {
    rq_ray r = make_ray(rng_float(&rng, 1, 15), rng_float(&rng, 1, 15), 2.0f, rng_float(&rng, -0.3f, 0.3f),
                        rng_float(&rng, -0.3f, 0.3f), -1.0f);
    rq_hit top = trace(scene, &r);
    CHECKF(top.prim == top0 || top.prim == top1, "from above %d: prim %u", i, (unsigned)top.prim);
    rq_hit below = trace(scene, (rq_ray[]){window(r, nextafterf(top.t, INFINITY), INFINITY)});
    CHECKF(below.prim < top0 && below.t > top.t, "from above %d: below prim %u", i, (unsigned)below.prim);
    rq_hit capped = trace(scene, (rq_ray[]){window(r, 0.0f, 1.5f)});
    CHECK(same_hit(&capped, &top));
    rq_hit between = trace(scene, (rq_ray[]){window(r, 1.25f, 1.75f)});
    CHECK(between.prim == RQ_INVALID_ID);
  }
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- barycentrics and hit points --------------------------------------------------------------- */

static void test_barycentrics(int structure) {
  test_mesh m;
  memset(&m, 0, sizeof m);
  /* Triangle 0 in the plane z = 0 with exact vertices; triangle 1 tilted in 3D, away from it. */
  const float p[2][3][3] = {{{1, 1, 0}, {3, 1, 0}, {1, 4, 0}},
                            {{10.3f, -0.2f, 0.1f}, {12.1f, 0.4f, -0.7f}, {9.5f, 1.9f, 0.8f}}};
  for (int t = 0; t < 2; t++) {
    uint32_t v0 = mesh_vertex(&m, p[t][0][0], p[t][0][1], p[t][0][2]);
    uint32_t v1 = mesh_vertex(&m, p[t][1][0], p[t][1][1], p[t][1][2]);
    uint32_t v2 = mesh_vertex(&m, p[t][2][0], p[t][2][1], p[t][2][2]);
    mesh_triangle(&m, v0, v1, v2);
  }
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  /* Straight down onto each vertex of triangle 0: u and v pick out the second and third vertex. */
  const float expect_uv[3][2] = {{0, 0}, {1, 0}, {0, 1}};
  for (int k = 0; k < 3; k++) {
    rq_ray r = make_ray(p[0][k][0], p[0][k][1], 2.0f, 0.0f, 0.0f, -1.0f);
    rq_hit h = trace(scene, &r);
    CHECKF(h.prim == 0, "vertex %d: prim %u", k, (unsigned)h.prim);
    CHECKF(fabsf(h.u - expect_uv[k][0]) <= 1e-6f && fabsf(h.v - expect_uv[k][1]) <= 1e-6f,
           "vertex %d: u %g v %g", k, (double)h.u, (double)h.v);
    /* The weights that should be zero are exactly zero there. */
    if (expect_uv[k][0] == 0.0f) {
      CHECKF(h.u == 0.0f, "vertex %d: u %a", k, (double)h.u);
    }
    if (expect_uv[k][1] == 0.0f) {
      CHECKF(h.v == 0.0f, "vertex %d: v %a", k, (double)h.v);
    }
    CHECKF(fabsf(h.t - 2.0f) <= 1e-6f, "vertex %d: t %g", k, (double)h.t);
  }
  /* Random points on both triangles from random directions: u, v match the barycentrics the point was
   * made from, and org + t*dir lands on (1-u-v)*p0 + u*p1 + v*p2. */
  uint64_t rng = 77;
  for (int i = 0; i < 2000; i++) {
    int t = i % 2;
    double b1, b2;
    do {
      b1 = rng_float(&rng, 0.001f, 0.998f);
      b2 = rng_float(&rng, 0.001f, 0.998f);
    } while (b1 + b2 > 0.999);
    double P[3], O[3];
    float dir[3];
    rng_dir(&rng, dir);
    double scale = t ? 3.0 : 1.0 + rng_float(&rng, 0.0f, 5.0f);
    for (int k = 0; k < 3; k++) {
      P[k] = p[t][0][k] + b1 * (p[t][1][k] - p[t][0][k]) + b2 * (p[t][2][k] - p[t][0][k]);
    }
    if (t == 0 && dir[2] > 0.0f) {
      dir[2] = -dir[2];
    }
    if (t == 0 && dir[2] > -0.05f) {
      dir[2] = -0.5f;
    }
    for (int k = 0; k < 3; k++) {
      O[k] = P[k] - scale * dir[k];
    }
    rq_ray r = make_ray((float)O[0], (float)O[1], (float)O[2], dir[0], dir[1], dir[2]);
    rq_hit h = trace(scene, &r);
    if (t == 1 && h.prim != 1) {
      /* A grazing ray may see the tilted triangle nearly edge-on; demand a hit only when it is not. */
      double e1[3], e2[3], n[3];
      for (int k = 0; k < 3; k++) {
        e1[k] = p[1][1][k] - p[1][0][k];
        e2[k] = p[1][2][k] - p[1][0][k];
      }
      n[0] = e1[1] * e2[2] - e1[2] * e2[1];
      n[1] = e1[2] * e2[0] - e1[0] * e2[2];
      n[2] = e1[0] * e2[1] - e1[1] * e2[0];
      double cosang = fabs(n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]) /
                      sqrt((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]));
      CHECKF(cosang < 0.05, "ray %d: missed triangle 1 (prim %u) at cos %g", i, (unsigned)h.prim, cosang);
      continue;
    }
    CHECKF(h.prim == (uint32_t)t, "ray %d: prim %u, expected %d", i, (unsigned)h.prim, t);
    if (h.prim != (uint32_t)t) {
      continue;
    }
    CHECKF(fabs(h.u - b1) <= 2e-4 && fabs(h.v - b2) <= 2e-4, "ray %d: u %g v %g, expected %g %g", i,
           (double)h.u, (double)h.v, b1, b2);
    CHECK(h.u >= 0.0f && h.v >= 0.0f && h.u + h.v <= 1.0f + 1e-6f);
    for (int k = 0; k < 3; k++) {
      double on_ray = (double)r.org[k] + (double)h.t * (double)r.dir[k];
      double on_tri = (1.0 - h.u - h.v) * p[t][0][k] + h.u * p[t][1][k] + h.v * p[t][2][k];
      CHECKF(fabs(on_ray - on_tri) <= 1e-4 * (1.0 + fabs(on_tri)), "ray %d axis %d: ray point %g, triangle point %g",
             i, k, on_ray, on_tri);
      CHECKF(fabs(on_ray - P[k]) <= 1e-4 * (1.0 + fabs(P[k])), "ray %d axis %d: hit %g, aimed at %g", i, k, on_ray,
             P[k]);
    }
  }
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- odd rays ---------------------------------------------------------------------------------- */

static void test_odd_rays(int structure) {
  test_mesh m = mesh_cube(4);
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  const rq_ray good = make_ray(0.3f, 0.2f, 5.0f, 0.01f, -0.02f, -1.0f);
  rq_hit ref = trace(scene, &good);
  CHECK(ref.prim != RQ_INVALID_ID);

  /* NaN in any one of the eight components: a miss, and occluded is false. */
  for (int k = 0; k < 8; k++) {
    rq_ray r = good;
    float *f = k < 3 ? &r.org[k] : k == 3 ? &r.tmin : k < 7 ? &r.dir[k - 4] : &r.tmax;
    *f = NAN;
    rq_hit h;
    memset(&h, 0x42, sizeof h);
    CHECKF(!rq_scene_intersect(scene, &r, &h), "NaN in component %d hit", k);
    CHECKF(is_exact_miss(&h), "NaN in component %d: not the exact miss", k);
    CHECKF(!rq_scene_occluded(scene, &r), "NaN in component %d occluded", k);
    rq_hit batch[2];
    rq_ray rays[2];
    rays[0] = r;
    rays[1] = good;
    CHECK_STATUS(rq_scene_intersect_n(scene, rays, batch, 2), RQ_STATUS_OK);
    CHECK(is_exact_miss(&batch[0]) && same_hit(&batch[1], &ref));
  }
  /* Infinite components: whatever the answer, intersect and occluded agree and nothing breaks. */
  for (int k = 0; k < 8; k++) {
    for (int sign = 0; sign < 2; sign++) {
      rq_ray r = good;
      float *f = k < 3 ? &r.org[k] : k == 3 ? &r.tmin : k < 7 ? &r.dir[k - 4] : &r.tmax;
      *f = sign ? -INFINITY : INFINITY;
      (void)trace(scene, &r);
    }
  }
  /* Zero direction (of either sign of zero): a miss, even from inside the closed cube. */
  const float zeros[2] = {0.0f, -0.0f};
  for (int s = 0; s < 8; s++) {
    rq_ray r = make_ray(0.1f, 0.2f, 0.3f, zeros[s & 1], zeros[(s >> 1) & 1], zeros[(s >> 2) & 1]);
    rq_hit h = trace(scene, &r);
    CHECKF(h.prim == RQ_INVALID_ID, "zero direction %d hit prim %u", s, (unsigned)h.prim);
    r.org[2] = 5.0f;
    h = trace(scene, &r);
    CHECK(h.prim == RQ_INVALID_ID);
  }
  /* Direction length does not matter: t scales, the hit does not. */
  const float scales[] = {1e-20f, 1e-3f, 0.5f, 3.0f, 1e3f, 1e20f};
  for (size_t s = 0; s < sizeof scales / sizeof scales[0]; s++) {
    rq_ray r = good;
    for (int k = 0; k < 3; k++) {
      r.dir[k] *= scales[s];
    }
    rq_hit h = trace(scene, &r);
    CHECKF(h.prim == ref.prim, "direction scaled by %g: prim %u, expected %u", (double)scales[s], (unsigned)h.prim,
           (unsigned)ref.prim);
    CHECKF(fabs((double)h.t * scales[s] - ref.t) <= 1e-5 * ref.t, "direction scaled by %g: t %g", (double)scales[s],
           (double)h.t);
    CHECKF(fabsf(h.u - ref.u) <= 1e-5f && fabsf(h.v - ref.v) <= 1e-5f, "direction scaled by %g: u %g v %g",
           (double)scales[s], (double)h.u, (double)h.v);
  }
  /* Axis-parallel rays from outside at each of the six faces, at lattice points (shared vertices and
   * edges of the faces) and off-lattice points; -0.0 in the zero components gives the same hit. */
  const float across[] = {-0.5f, 0.0f, 0.5f, -0.3f, 0.7f, 0.25f, -0.75f};
  const size_t na = sizeof across / sizeof across[0];
  for (int axis = 0; axis < 3; axis++) {
    for (int sign = -1; sign <= 1; sign += 2) {
      for (size_t i = 0; i < na; i++) {
        for (size_t j = 0; j < na; j++) {
          rq_ray r = make_ray(0, 0, 0, 0, 0, 0);
          r.org[axis] = -5.0f * (float)sign;
          r.org[(axis + 1) % 3] = across[i];
          r.org[(axis + 2) % 3] = across[j];
          r.dir[axis] = (float)sign;
          rq_hit h = trace(scene, &r);
          CHECKF(h.prim != RQ_INVALID_ID, "axis %d sign %d at (%g, %g): miss", axis, sign, (double)across[i],
                 (double)across[j]);
          CHECKF(fabsf(h.t - 4.0f) <= 1e-5f, "axis %d sign %d at (%g, %g): t %g", axis, sign, (double)across[i],
                 (double)across[j], (double)h.t);
          rq_ray neg = r;
          neg.dir[(axis + 1) % 3] = -0.0f;
          neg.dir[(axis + 2) % 3] = -0.0f;
          rq_hit hn = trace(scene, &neg);
          CHECKF(hn.prim == h.prim && hn.t == h.t && hn.u == h.u && hn.v == h.v,
                 "axis %d sign %d at (%g, %g): -0.0 direction gives a different hit", axis, sign,
                 (double)across[i], (double)across[j]);
          /* Leaving the cube from the centre along the same line. */
          rq_ray out = r;
          out.org[axis] = 0.0f;
          rq_hit ho = trace(scene, &out);
          CHECKF(ho.prim != RQ_INVALID_ID && fabsf(ho.t - 1.0f) <= 1e-5f, "axis %d sign %d from inside: prim %u t %g",
                 axis, sign, (unsigned)ho.prim, (double)ho.t);
        }
      }
    }
  }
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- closed meshes never leak ----------------------------------------------------------------- */


static void test_watertight(int structure) {
  const int sizes[] = {1, 4, 16};
  for (size_t si = 0; si < sizeof sizes / sizeof sizes[0]; si++) {
    int n = sizes[si];
    test_mesh m = mesh_cube(n);
    rq_scene *scene = test_build(&m, structure);
    if (!scene) {
      mesh_free(&m);
      continue;
    }
    long misses = 0;
    /* Rays from the centre through every lattice point of the surface (mesh vertices and the
     * midpoints of mesh edges) and from outside back through them. */
    int fine = 2 * n;
    for (int i = 0; i <= fine; i++) {
      for (int j = 0; j <= fine; j++) {
        for (int k = 0; k <= fine; k++) {
          if (i != 0 && i != fine && j != 0 && j != fine && k != 0 && k != fine) {
            continue;
          }
          float q[3] = {-1.0f + 2.0f * (float)i / (float)fine, -1.0f + 2.0f * (float)j / (float)fine,
                        -1.0f + 2.0f * (float)k / (float)fine};
          rq_ray r = make_ray(0, 0, 0, q[0], q[1], q[2]);
          rq_hit h = trace(scene, &r);
          if (h.prim == RQ_INVALID_ID) {
            misses++;
            CHECKF(0, "cube %d: ray from the centre through (%g, %g, %g) missed", n, (double)q[0], (double)q[1],
                   (double)q[2]);
          } else {
            CHECKF(fabsf(h.t - 1.0f) <= 1e-5f, "cube %d: through (%g, %g, %g): t %g", n, (double)q[0],
                   (double)q[1], (double)q[2], (double)h.t);
          }
          rq_ray in = make_ray(3 * q[0], 3 * q[1], 3 * q[2], -q[0], -q[1], -q[2]);
          h = trace(scene, &in);
          CHECKF(h.prim != RQ_INVALID_ID && fabsf(h.t - 2.0f) <= 1e-5f,
                 "cube %d: ray from outside through (%g, %g, %g): prim %u t %g", n, (double)q[0], (double)q[1],
                 (double)q[2], (unsigned)h.prim, (double)h.t);
        }
      }
    }
    /* Random origins inside, random directions, and directions aimed at lattice points from off-centre
     * origins (which pass near, not through, the shared edges): every one hits the surface. */
    uint64_t rng = 4242 + (uint64_t)n;
    for (int i = 0; i < 3000; i++) {
      rq_ray r = make_ray(rng_float(&rng, -0.99f, 0.99f), rng_float(&rng, -0.99f, 0.99f),
                          rng_float(&rng, -0.99f, 0.99f), 0, 0, 0);
      if (i % 3 == 0) {
        int l[3];
        for (int k = 0; k < 3; k++) {
          l[k] = (int)(rng_next(&rng) % (uint64_t)(fine + 1));
        }
        l[rng_next(&rng) % 3] = (rng_next(&rng) & 1) ? fine : 0;
        for (int k = 0; k < 3; k++) {
          r.dir[k] = (-1.0f + 2.0f * (float)l[k] / (float)fine) - r.org[k];
        }
      } else if (i % 3 == 1) {
        /* Axis-parallel and in-plane directions. */
        r.dir[i % 3] = (rng_next(&rng) & 1) ? 1.0f : -1.0f;
        r.dir[(i + 1) % 3] = (i % 5 == 0) ? rng_float(&rng, -1, 1) : 0.0f;
      } else {
        rng_dir(&rng, r.dir);
      }
      if (r.dir[0] == 0.0f && r.dir[1] == 0.0f && r.dir[2] == 0.0f) {
        continue;
      }
      rq_hit h = trace(scene, &r);
      if (h.prim == RQ_INVALID_ID) {
        misses++;
        CHECKF(0, "cube %d: ray %d from inside leaked: org (%a, %a, %a) dir (%a, %a, %a)", n, i, (double)r.org[0],
               (double)r.org[1], (double)r.org[2], (double)r.dir[0], (double)r.dir[1], (double)r.dir[2]);
        continue;
      }
      CHECK(h.t > 0.0f);
      double big = 0.0;
      for (int k = 0; k < 3; k++) {
        double c = fabs((double)r.org[k] + (double)h.t * (double)r.dir[k]);
        big = c > big ? c : big;
      }
      CHECKF(fabs(big - 1.0) <= 1e-4, "cube %d: ray %d hit at a point %g from the centre (max norm)", n, i, big);
      {
        static const double lo[3] = {-1, -1, -1}, hi[3] = {1, 1, 1};
        char label[32];
        snprintf(label, sizeof label, "cube %d", n);
        CHECK_EXIT(r, h, lo, hi, label, i);
      }
    }
    CHECKF(misses == 0, "cube %d: %ld rays leaked", n, misses);
    rq_scene_free(scene);
    mesh_free(&m);
  }

  /* A tessellated plane: rays through every interior vertex and edge midpoint, straight and oblique
   * with exactly representable origins, hit. */
  const int n = 12;
  test_mesh plane = mesh_plane(n);
  rq_scene *scene = test_build(&plane, structure);
  if (scene) {
    const float dirs[][3] = {{0, 0, -1}, {0.25f, -0.5f, -1}, {-0.75f, 0.125f, -0.5f}, {1, 1, -1},
                             {-1, 0, -1}, {0, 2, -0.25f}};
    for (int y2 = 2; y2 <= 2 * n - 2; y2++) {
      for (int x2 = 2; x2 <= 2 * n - 2; x2++) {
        float x = 0.5f * (float)x2, y = 0.5f * (float)y2;
        for (size_t k = 0; k < sizeof dirs / sizeof dirs[0]; k++) {
          const float *dd = dirs[k];
          rq_ray r = make_ray(x - dd[0], y - dd[1], -dd[2], dd[0], dd[1], dd[2]);
          rq_hit h = trace(scene, &r);
          CHECKF(h.prim != RQ_INVALID_ID && fabsf(h.t - 1.0f) <= 1e-6f, "plane: through (%g, %g) dir %u: prim %u t %g",
                 (double)x, (double)y, (unsigned)k, (unsigned)h.prim, (double)h.t);
          /* The same line from below, upwards. */
          rq_ray up = make_ray(x + dd[0], y + dd[1], dd[2], -dd[0], -dd[1], -dd[2]);
          h = trace(scene, &up);
          CHECKF(h.prim != RQ_INVALID_ID, "plane: up through (%g, %g) dir %u missed", (double)x, (double)y,
                 (unsigned)k);
        }
      }
    }
    rq_scene_free(scene);
  }
  mesh_free(&plane);
}

/* A ray starting on a surface: t = 0 is inside [0, inf], so it hits there; a window starting just
 * after 0 does not see that surface. */
static void test_origin_on_surface(int structure) {
  test_mesh m = mesh_plane(4);
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  const float pts[][2] = {{0.3f, 0.6f}, {1.0f, 1.0f}, {2.5f, 1.0f}, {1.5f, 1.5f}, {3.25f, 0.125f}};
  for (size_t p = 0; p < sizeof pts / sizeof pts[0]; p++) {
    for (int up = 0; up < 2; up++) {
      rq_ray r = make_ray(pts[p][0], pts[p][1], 0.0f, 0.125f, -0.25f, up ? 1.0f : -1.0f);
      rq_hit h = trace(scene, &r);
      CHECKF(h.prim != RQ_INVALID_ID && h.t == 0.0f, "point %u %s: prim %u t %g", (unsigned)p, up ? "up" : "down",
             (unsigned)h.prim, (double)h.t);
      h = trace(scene, (rq_ray[]){window(r, FLT_MIN, INFINITY)});
      CHECKF(h.prim == RQ_INVALID_ID, "point %u %s, tmin > 0: prim %u t %g", (unsigned)p, up ? "up" : "down",
             (unsigned)h.prim, (double)h.t);
    }
  }
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- ties ---------------------------------------------------------------------------------------- */

static void test_ties(int structure) {
  test_mesh m = mesh_soup(31, 100); /* ids 0..99, all inside [-3.5, 3.5]^3 */
  uint32_t a = mesh_vertex(&m, -10, -10, 10), b = mesh_vertex(&m, 10, -10, 10), c = mesh_vertex(&m, -10, 10, 10);
  uint32_t a2 = mesh_vertex(&m, -10, -10, 10), b2 = mesh_vertex(&m, 10, -10, 10), c2 = mesh_vertex(&m, -10, 10, 10);
  uint32_t first = mesh_triangle(&m, a, b, c); /* 100 */
  uint32_t other = mesh_triangle(&m, mesh_vertex(&m, 50, 50, 50), mesh_vertex(&m, 51, 50, 50),
                                 mesh_vertex(&m, 50, 51, 50)); /* 101, elsewhere */
  uint32_t dup_same = mesh_triangle(&m, a, b, c);     /* 102: the same indices */
  uint32_t dup_copy = mesh_triangle(&m, a2, b2, c2);  /* 103: copies of the vertices */
  (void)other;
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  uint64_t rng = 8;
  for (int i = 0; i < 1000; i++) {
    /* A point well inside the duplicated triangle (x, y > -9, x + y < -1) at z = 10. */
    float x, y;
    do {
      x = rng_float(&rng, -9.0f, 8.0f);
      y = rng_float(&rng, -9.0f, 8.0f);
    } while (x + y > -1.0f);
    float dx = rng_float(&rng, -0.1f, 0.1f), dy = rng_float(&rng, -0.1f, 0.1f);
    rq_ray r;
    if (i % 4 != 3) {
      /* From above: nothing lies between the origin and the triangle. */
      r = make_ray(x - 10.0f * dx, y - 10.0f * dy, 20.0f, dx, dy, -1.0f);
    } else {
      /* From below, through the soup's region; past the soup (z > 4) only the duplicates remain. */
      r = make_ray(0.2f * x, 0.2f * y, 0.0f, 0.08f * x, 0.08f * y, 1.0f);
      r.tmin = 4.0f;
    }
    rq_hit h = trace(scene, &r);
    CHECKF(h.prim == first, "ray %d: tie went to prim %u instead of %u (duplicates %u, %u)", i, (unsigned)h.prim,
           (unsigned)first, (unsigned)dup_same, (unsigned)dup_copy);
  }
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- a double-precision reference (Moller-Trumbore), for an independent opinion ---------------- */

typedef struct ref_hit {
  int clear_hit, clear_miss;
  double t, u, v;
} ref_hit;

static ref_hit reference(const test_mesh *m, uint32_t prim, const rq_ray *r) {
  ref_hit out;
  memset(&out, 0, sizeof out);
  const float *p0 = &m->v[3 * m->idx[3 * prim]], *p1 = &m->v[3 * m->idx[3 * prim + 1]],
              *p2 = &m->v[3 * m->idx[3 * prim + 2]];
  double e1[3], e2[3], tv[3], pv[3], qv[3], d[3];
  for (int k = 0; k < 3; k++) {
    e1[k] = (double)p1[k] - p0[k];
    e2[k] = (double)p2[k] - p0[k];
    tv[k] = (double)r->org[k] - p0[k];
    d[k] = r->dir[k];
  }
  pv[0] = d[1] * e2[2] - d[2] * e2[1];
  pv[1] = d[2] * e2[0] - d[0] * e2[2];
  pv[2] = d[0] * e2[1] - d[1] * e2[0];
  double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
  double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  double el = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]) * sqrt(e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]);
  if (fabs(det) <= 1e-3 * dl * el) {
    /* Nearly edge-on: no clear opinion. */
    return out;
  }
  double inv = 1.0 / det;
  out.u = (tv[0] * pv[0] + tv[1] * pv[1] + tv[2] * pv[2]) * inv;
  qv[0] = tv[1] * e1[2] - tv[2] * e1[1];
  qv[1] = tv[2] * e1[0] - tv[0] * e1[2];
  qv[2] = tv[0] * e1[1] - tv[1] * e1[0];
  out.v = (d[0] * qv[0] + d[1] * qv[1] + d[2] * qv[2]) * inv;
  out.t = (e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) * inv;
  double margin = fmin(fmin(out.u, out.v), 1.0 - out.u - out.v);
  double tol = 1e-4 * (1.0 + fabs(out.t));
  int inside_window = out.t >= (double)r->tmin + tol && out.t <= (double)r->tmax - tol;
  int outside_window = out.t < (double)r->tmin - tol || out.t > (double)r->tmax + tol;
  out.clear_hit = margin > 1e-4 && inside_window;
  out.clear_miss = margin < -1e-4 || outside_window;
  return out;
}

static void test_against_reference(int structure) {
  test_mesh m = mesh_soup(2024, 400);
  rq_scene *scene = test_build(&m, structure);
  if (!scene) {
    mesh_free(&m);
    return;
  }
  uint64_t rng = 555;
  int hits = 0;
  for (int i = 0; i < 1500; i++) {
    rq_ray r = make_ray(rng_float(&rng, -5, 5), rng_float(&rng, -5, 5), rng_float(&rng, -5, 5), 0, 0, 0);
    for (int k = 0; k < 3; k++) {
      r.dir[k] = rng_float(&rng, -2, 2) - r.org[k]; /* t = 1 at a point inside the soup's box */
    }
    if (i % 3 == 1) {
      r.tmin = rng_float(&rng, 0.0f, 0.8f);
      r.tmax = r.tmin + rng_float(&rng, 0.0f, 0.6f);
    } else if (i % 3 == 2) {
      r.tmin = rng_float(&rng, 0.5f, 1.0f);
    }
    rq_hit h = trace(scene, &r);
    hits += h.prim != RQ_INVALID_ID;
    /* The closest clear hit by the reference. */
    double best_t = INFINITY;
    uint32_t best = RQ_INVALID_ID;
    for (uint32_t p = 0; p < m.nt; p++) {
      ref_hit rh = reference(&m, p, &r);
      if (rh.clear_hit && rh.t < best_t) {
        best_t = rh.t;
        best = p;
      }
    }
    if (best != RQ_INVALID_ID) {
      CHECKF(h.prim != RQ_INVALID_ID, "ray %d: missed, the reference hits prim %u at t %g", i, (unsigned)best, best_t);
      CHECKF(h.prim == RQ_INVALID_ID || (double)h.t <= best_t + 1e-4 * (1.0 + best_t),
             "ray %d: hit prim %u at t %g behind the reference's prim %u at t %g", i, (unsigned)h.prim, (double)h.t,
             (unsigned)best, best_t);
    }
    if (h.prim != RQ_INVALID_ID) {
      CHECKF(h.prim < m.nt, "ray %d: prim %u out of range", i, (unsigned)h.prim);
      if (h.prim >= m.nt) {
        continue;
      }
      ref_hit rh = reference(&m, h.prim, &r);
      CHECKF(!rh.clear_miss, "ray %d: hit prim %u at t %g where the reference sees a clear miss (t %g u %g v %g)", i,
             (unsigned)h.prim, (double)h.t, rh.t, rh.u, rh.v);
      if (rh.clear_hit) {
        CHECKF(fabs(h.t - rh.t) <= 1e-4 * (1.0 + fabs(rh.t)) && fabs(h.u - rh.u) <= 1e-3 && fabs(h.v - rh.v) <= 1e-3,
               "ray %d prim %u: t %g u %g v %g, reference t %g u %g v %g", i, (unsigned)h.prim, (double)h.t,
               (double)h.u, (double)h.v, rh.t, rh.u, rh.v);
      }
    }
  }
  CHECKF(hits > 200, "only %d of 1500 rays hit the soup: the test is not testing much", hits);
  rq_scene_free(scene);
  mesh_free(&m);
}

/* ---- batch == single, occluded == intersect, structures agree ---------------------------------- */

#define BATCH 3000

/* Rays from a box around [lo, hi] (half its size again on each side) aimed at points inside it, with
 * a mix of windows and some axis-parallel directions. */
static void make_rays(uint64_t seed, rq_ray *rays, int count, const float lo[3], const float hi[3]) {
  uint64_t rng = seed;
  for (int i = 0; i < count; i++) {
    float org[3], dir[3];
    for (int k = 0; k < 3; k++) {
      float pad = 0.5f * (hi[k] - lo[k]) + 0.5f;
      org[k] = rng_float(&rng, lo[k] - pad, hi[k] + pad);
      dir[k] = rng_float(&rng, lo[k], hi[k]) - org[k];
    }
    rays[i] = make_ray(org[0], org[1], org[2], dir[0], dir[1], dir[2]);
    switch (i % 6) {
    case 1:
      rays[i].tmax = rng_float(&rng, 0.0f, 1.5f);
      break;
    case 2:
      rays[i].tmin = rng_float(&rng, 0.0f, 1.0f);
      break;
    case 3:
      rays[i].tmin = rng_float(&rng, 0.0f, 1.0f);
      rays[i].tmax = rays[i].tmin + rng_float(&rng, 0.0f, 0.5f);
      break;
    case 4:
      /* Axis-parallel: keep one component of the direction. */
      rays[i].dir[(i / 6) % 3] = 0.0f;
      rays[i].dir[(i / 6 + 1) % 3] = 0.0f;
      break;
    case 5:
      /* Random direction from the origin, aimed at nothing in particular. */
      rng_dir(&rng, rays[i].dir);
      break;
    default:
      break;
    }
  }
}

static void test_batch_and_structures(int structure) {
  test_mesh meshes[3];
  meshes[0] = mesh_cube(8);
  meshes[1] = mesh_plane(24);
  meshes[2] = mesh_soup(9, 600);
  static rq_ray rays[BATCH];
  static rq_hit batch[BATCH], single[BATCH], other[BATCH];
  for (int mi = 0; mi < 3; mi++) {
    rq_scene *scene = test_build(&meshes[mi], structure);
    if (!scene) {
      continue;
    }
    static const float box_lo[3][3] = {{-1, -1, -1}, {0, 0, 0}, {-3.5f, -3.5f, -3.5f}};
    static const float box_hi[3][3] = {{1, 1, 1}, {24, 24, 0}, {3.5f, 3.5f, 3.5f}};
    make_rays(100 + (uint64_t)mi, rays, BATCH, box_lo[mi], box_hi[mi]);
    memset(batch, 0x99, sizeof batch);
    CHECK_STATUS(rq_scene_intersect_n(scene, rays, batch, BATCH), RQ_STATUS_OK);
    int hits = 0;
    for (int i = 0; i < BATCH; i++) {
      memset(&single[i], 0x55, sizeof single[i]);
      int hit = rq_scene_intersect(scene, &rays[i], &single[i]);
      hits += hit;
      CHECKF(hit == rq_scene_occluded(scene, &rays[i]), "mesh %d ray %d: intersect %d, occluded %d", mi, i, hit,
             !hit);
      if (!hit) {
        CHECK(is_exact_miss(&single[i]));
      }
    }
    CHECKF(memcmp(batch, single, sizeof batch) == 0, "mesh %d: rq_scene_intersect_n differs from single calls", mi);
    CHECKF(hits > BATCH / 4 && hits < BATCH * 9 / 10, "mesh %d: %d of %d rays hit: the rays test too little", mi,
           hits, BATCH);
    /* Batches of every small size and at every offset give the same answers. */
    for (int n = 1; n <= 7; n++) {
      for (int off = 0; off + n <= 40; off += n) {
        rq_hit part[7];
        CHECK_STATUS(rq_scene_intersect_n(scene, rays + off, part, (size_t)n), RQ_STATUS_OK);
        CHECK(memcmp(part, single + off, (size_t)n * sizeof part[0]) == 0);
      }
    }

    /* Against the grid and the kd-tree: bit for bit. */
    for (int s = RQ_STRUCTURE_GRID; s <= RQ_STRUCTURE_KDTREE; s++) {
      rq_mesh_desc d = mesh_desc(&meshes[mi]);
      rq_build_options o;
      rq_build_options_init(&o);
      o.structure = (rq_structure)s;
      rq_scene *alt = NULL;
      rq_status st = rq_scene_build(&d, &o, NULL, &alt);
      CHECKF(st == RQ_STATUS_OK, "mesh %d structure %s: %u (%s)", mi, structure_name(s), (unsigned)st,
             rq_status_str(st));
      if (!alt) {
        continue;
      }
      CHECK_STATUS(rq_scene_intersect_n(alt, rays, other, BATCH), RQ_STATUS_OK);
      int differ = 0;
      for (int i = 0; i < BATCH; i++) {
        if (!same_hit(&other[i], &batch[i])) {
          if (differ++ < 3) {
            fprintf(stderr, "    mesh %d ray %d: %s vs %s\n", mi, i, structure_name(structure), structure_name(s));
            print_hit(structure_name(structure), &batch[i]);
            print_hit(structure_name(s), &other[i]);
          }
        }
      }
      CHECKF(differ == 0, "mesh %d: %d rays differ between %s and %s", mi, differ, structure_name(structure),
             structure_name(s));
      rq_scene_free(alt);
    }
    rq_scene_free(scene);
  }
  for (int mi = 0; mi < 3; mi++) {
    mesh_free(&meshes[mi]);
  }
}

int main(void) {
  for (size_t i = 0; i < sizeof structures / sizeof structures[0]; i++) {
    int s = structures[i];
    long before = test_failures;
    test_window(s);
    test_barycentrics(s);
    test_odd_rays(s);
    test_watertight(s);
    test_origin_on_surface(s);
    test_ties(s);
    test_against_reference(s);
    test_batch_and_structures(s);
    printf("queries with %s: %ld failures\n", structure_name(s), test_failures - before);
  }
  /* The kd-tree: not in every build yet. When it builds, the same suite must pass on it. */
  {
    test_mesh m = mesh_cube(2);
    rq_mesh_desc d = mesh_desc(&m);
    rq_build_options o;
    rq_build_options_init(&o);
    o.structure = RQ_STRUCTURE_KDTREE;
    rq_scene *scene = (rq_scene *)test_sentinel();
    rq_status st = rq_scene_build(&d, &o, NULL, &scene);
    CHECKF(st == RQ_STATUS_OK, "kdtree: %u (%s)", (unsigned)st, rq_status_str(st));
    if (st == RQ_STATUS_OK) {
      rq_scene_free(scene);
      long before = test_failures;
      test_window(RQ_STRUCTURE_KDTREE);
      test_barycentrics(RQ_STRUCTURE_KDTREE);
      test_odd_rays(RQ_STRUCTURE_KDTREE);
      test_watertight(RQ_STRUCTURE_KDTREE);
      test_origin_on_surface(RQ_STRUCTURE_KDTREE);
      test_ties(RQ_STRUCTURE_KDTREE);
      test_against_reference(RQ_STRUCTURE_KDTREE);
      test_batch_and_structures(RQ_STRUCTURE_KDTREE);
      printf("queries with kdtree: %ld failures\n", test_failures - before);
    } else {
      CHECK(scene == (rq_scene *)test_sentinel());
      printf("queries with kdtree: skipped (%s)\n", rq_status_str(st));
    }
    mesh_free(&m);
  }
  return test_finish("queries");
}
