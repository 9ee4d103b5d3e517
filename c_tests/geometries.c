/* geometries.c: scenes of several meshes through the C ABI (DESIGN §4.1): geometry ids and local
 * triangle ids, masks, culling by geometry and by ray (both faces), an alpha-test filter in closest
 * and any-hit queries, the geometric normal, rq_scene_set_vertices against a fresh build of the moved
 * meshes, batched queries against single calls, and the refusals. Runs for the grid, the kd-tree and
 * AUTO. */
#include "common.h"

static const int structures[] = {RQ_STRUCTURE_GRID, RQ_STRUCTURE_KDTREE, RQ_STRUCTURE_AUTO};
static const char *structure_name(int s) {
  return s == RQ_STRUCTURE_GRID ? "grid" : s == RQ_STRUCTURE_KDTREE ? "kdtree" : "auto";
}

/* The three meshes: a closed cube [-1, 1]^3 (geometry 0), a 6 x 6 plane at z = 0 over [0, 6]^2
 * (geometry 1, partly inside the cube) and a random soup (geometry 2). */
typedef struct parts {
  test_mesh m[3];
} parts;

static parts make_parts(void) {
  parts p;
  p.m[0] = mesh_cube(2);
  p.m[1] = mesh_plane(6);
  p.m[2] = mesh_soup(99, 60);
  return p;
}

static void free_parts(parts *p) {
  for (int g = 0; g < 3; g++) {
    mesh_free(&p->m[g]);
  }
}

static rq_build_options options_for(int structure) {
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = (rq_structure)structure;
  o.expected_rays = 1000000;
  /* The check after a kd-tree build priced from counted work, not timed: two scenes built alike
   * then choose alike. */
  o.clock = NULL;
  return o;
}

/* Builds the scene of `count` geometries with the given masks, flags and filters (NULL arrays: the
 * defaults). */
static rq_scene *build(const parts *p, int count, const uint32_t *masks, const uint32_t *flags, rq_filter_fn filter,
                       void *filter_user, int filtered, int structure) {
  rq_geometry_desc d[3];
  for (int g = 0; g < count; g++) {
    rq_geometry_desc_init(&d[g]);
    d[g].mesh = mesh_desc(&p->m[g]);
    if (masks) {
      d[g].mask = masks[g];
    }
    if (flags) {
      d[g].flags = flags[g];
    }
    if (g == filtered) {
      d[g].filter = filter;
      d[g].filter_user = filter_user;
    }
  }
  rq_build_options o = options_for(structure);
  rq_scene *s = NULL;
  rq_status st = rq_scene_build_geometries(d, (size_t)count, &o, NULL, &s);
  CHECKF(st == RQ_STATUS_OK, "build_geometries (%s): %s", structure_name(structure), rq_status_str(st));
  return st == RQ_STATUS_OK ? s : NULL;
}

static rq_ray_ex ray_ex(rq_ray r, uint32_t mask, uint32_t flags) {
  rq_ray_ex x;
  memcpy(x.org, r.org, sizeof x.org);
  memcpy(x.dir, r.dir, sizeof x.dir);
  x.tmin = r.tmin;
  x.tmax = r.tmax;
  x.mask = mask;
  x.flags = flags;
  return x;
}

static int same_hit_ex(const rq_hit_ex *a, const rq_hit_ex *b) { return memcmp(a, b, sizeof *a) == 0; }

static int is_miss_ex(const rq_hit_ex *h) {
  return isinf(h->t) && h->t > 0 && float_bits(h->u) == 0 && float_bits(h->v) == 0 && h->prim == RQ_INVALID_ID &&
         h->geom == RQ_INVALID_ID && float_bits(h->ng[0]) == 0 && float_bits(h->ng[1]) == 0 &&
         float_bits(h->ng[2]) == 0;
}

static rq_hit_ex trace_ex(const rq_scene *s, const rq_ray_ex *r) {
  rq_hit_ex h;
  memset(&h, 0xAB, sizeof h);
  bool hit = rq_scene_intersect_ex(s, r, &h);
  CHECK(hit == (h.prim != RQ_INVALID_ID));
  CHECK(rq_scene_occluded_ex(s, r) == hit);
  return h;
}

/* Rays that meet the parts from every side: from a box around them towards random points of it. */
static rq_ray random_ray(uint64_t *rng) {
  float o[3], t[3];
  for (int k = 0; k < 3; k++) {
    o[k] = rng_float(rng, -3.0f, 7.0f);
    t[k] = rng_float(rng, -1.5f, 5.0f);
  }
  rq_ray r = make_ray(o[0], o[1], o[2], t[0] - o[0], t[1] - o[1], t[2] - o[2]);
  return r;
}

#define RAYS 3000

/* ---- ids: a hit of the several-geometry scene names the geometry and its own triangle ---------- */

static void test_ids(int structure) {
  parts p = make_parts();
  rq_scene *s = build(&p, 3, NULL, NULL, NULL, NULL, -1, structure);
  rq_scene *alone[3] = {NULL, NULL, NULL};
  for (int g = 0; g < 3; g++) {
    rq_mesh_desc d = mesh_desc(&p.m[g]);
    rq_build_options o = options_for(structure);
    CHECK_STATUS(rq_scene_build(&d, &o, NULL, &alone[g]), RQ_STATUS_OK);
  }
  if (!s || !alone[0] || !alone[1] || !alone[2]) {
    goto done;
  }
  rq_scene_report rep;
  memset(&rep, 0, sizeof rep);
  rep.struct_size = sizeof rep;
  CHECK_STATUS(rq_scene_report_get(s, &rep), RQ_STATUS_OK);
  CHECK(rep.geometry_count == 3);
  CHECK(rep.triangle_count == p.m[0].nt + p.m[1].nt + p.m[2].nt);
  CHECK_STATUS(rq_scene_report_get(alone[1], &rep), RQ_STATUS_OK);
  CHECK(rep.geometry_count == 1);
  uint64_t rng = 7;
  int per[3] = {0, 0, 0};
  for (int i = 0; i < RAYS; i++) {
    rq_ray r = random_ray(&rng);
    rq_ray_ex x = ray_ex(r, 0xFFFFFFFFu, 0);
    rq_hit_ex h = trace_ex(s, &x);
    rq_hit plain = trace(s, &r);
    CHECK((h.prim == RQ_INVALID_ID) == (plain.prim == RQ_INVALID_ID));
    if (h.prim == RQ_INVALID_ID) {
      CHECK(is_miss_ex(&h));
      continue;
    }
    CHECKF(h.geom < 3, "ray %d: geom %u", i, (unsigned)h.geom);
    if (h.geom >= 3) {
      continue;
    }
    per[h.geom]++;
    /* The plain query counts triangles across the geometries in order. */
    uint32_t start = h.geom == 0 ? 0 : h.geom == 1 ? (uint32_t)p.m[0].nt : (uint32_t)(p.m[0].nt + p.m[1].nt);
    CHECKF(plain.prim == start + h.prim, "ray %d: plain prim %u, geom %u prim %u", i, (unsigned)plain.prim,
           (unsigned)h.geom, (unsigned)h.prim);
    CHECK(float_bits(plain.t) == float_bits(h.t) && float_bits(plain.u) == float_bits(h.u) &&
          float_bits(plain.v) == float_bits(h.v));
    /* The geometry alone is hit on the same triangle at the same t, or nearer (something of another
     * geometry cannot make it nearer). */
    rq_hit a = trace(alone[h.geom], &r);
    CHECKF(a.prim != RQ_INVALID_ID && a.t <= h.t, "ray %d: geometry %u alone: prim %u t %g, in the scene t %g", i,
           (unsigned)h.geom, (unsigned)a.prim, (double)a.t, (double)h.t);
    if (a.t == h.t) {
      CHECKF(a.prim == h.prim, "ray %d: alone prim %u, in the scene %u", i, (unsigned)a.prim, (unsigned)h.prim);
    }
    /* ng = (v1 - v0) x (v2 - v0) of the triangle named. */
    const test_mesh *m = &p.m[h.geom];
    const uint32_t *tri = &m->idx[3 * h.prim];
    const float *v0 = &m->v[3 * tri[0]], *v1 = &m->v[3 * tri[1]], *v2 = &m->v[3 * tri[2]];
    double e1[3], e2[3], n[3];
    for (int k = 0; k < 3; k++) {
      e1[k] = (double)v1[k] - v0[k];
      e2[k] = (double)v2[k] - v0[k];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; k++) {
      CHECKF(fabs((double)h.ng[k] - n[k]) <= 1e-6 * len, "ray %d: ng[%d] %g, recomputed %g", i, k,
             (double)h.ng[k], n[k]);
    }
  }
  CHECKF(per[0] > 100 && per[1] > 100 && per[2] > 20, "hits per geometry %d %d %d", per[0], per[1], per[2]);
done:
  for (int g = 0; g < 3; g++) {
    rq_scene_free(alone[g]);
  }
  rq_scene_free(s);
  free_parts(&p);
}

/* ---- masks: a ray sees exactly the geometries its mask shares a bit with ------------------------ */

static void test_masks(int structure) {
  parts p = make_parts();
  const uint32_t masks[3] = {1, 2, 4 | 1};
  rq_scene *s = build(&p, 3, masks, NULL, NULL, NULL, -1, structure);
  /* The reference: scenes of the subsets, built with the same ids (a geometry left out is empty). */
  if (!s) {
    free_parts(&p);
    return;
  }
  uint64_t rng = 11;
  int differs = 0;
  for (uint32_t mask = 0; mask < 8; mask++) {
    parts q;
    test_mesh empty;
    memset(&empty, 0, sizeof empty);
    for (int g = 0; g < 3; g++) {
      q.m[g] = (mask & masks[g]) ? p.m[g] : empty;
    }
    rq_scene *subset = build(&q, 3, NULL, NULL, NULL, NULL, -1, structure);
    if (!subset) {
      continue;
    }
    for (int i = 0; i < RAYS / 4; i++) {
      rq_ray r = random_ray(&rng);
      rq_ray_ex x = ray_ex(r, mask, 0);
      rq_ray_ex all = ray_ex(r, 0xFFFFFFFFu, 0);
      rq_hit_ex got = trace_ex(s, &x), want = trace_ex(subset, &all), open = trace_ex(s, &all);
      CHECKF(same_hit_ex(&got, &want), "mask %u ray %d: geom %u prim %u, the subset's geom %u prim %u", (unsigned)mask,
             i, (unsigned)got.geom, (unsigned)got.prim, (unsigned)want.geom, (unsigned)want.prim);
      differs += !same_hit_ex(&got, &open);
    }
    rq_scene_free(subset);
  }
  CHECKF(differs > 200, "masks changed only %d answers", differs);
  rq_scene_free(s);
  free_parts(&p);
}

/* ---- culling: by geometry and by ray, front and back -------------------------------------------- */

/* True when the ray meets the hit's face from the front: d . ng < 0 (the vertices counter-clockwise
 * as the ray sees them); `clear` is false when the sign is too close to call in double. */
static int front_of(const rq_ray *r, const rq_hit_ex *h, int *clear) {
  double dot = 0, dd = 0, nn = 0;
  for (int k = 0; k < 3; k++) {
    dot += (double)r->dir[k] * h->ng[k];
    dd += (double)r->dir[k] * r->dir[k];
    nn += (double)h->ng[k] * h->ng[k];
  }
  *clear = fabs(dot) > 1e-5 * sqrt(dd * nn);
  return dot < 0;
}

static void test_culling(int structure) {
  parts p = make_parts();
  rq_scene *open = build(&p, 3, NULL, NULL, NULL, NULL, -1, structure);
  const uint32_t cull_back[3] = {RQ_GEOMETRY_CULL_BACK_FACES, RQ_GEOMETRY_CULL_BACK_FACES, RQ_GEOMETRY_CULL_BACK_FACES};
  const uint32_t cull_front[3] = {RQ_GEOMETRY_CULL_FRONT_FACES, RQ_GEOMETRY_CULL_FRONT_FACES,
                                  RQ_GEOMETRY_CULL_FRONT_FACES};
  rq_scene *by_geometry[2] = {build(&p, 3, NULL, cull_back, NULL, NULL, -1, structure),
                              build(&p, 3, NULL, cull_front, NULL, NULL, -1, structure)};
  const uint32_t ray_flags[2] = {RQ_RAY_CULL_BACK_FACES, RQ_RAY_CULL_FRONT_FACES};
  int seen[2] = {0, 0}, skipped = 0;
  uint64_t rng = 13;
  if (!open || !by_geometry[0] || !by_geometry[1]) {
    goto done;
  }
  for (int i = 0; i < RAYS; i++) {
    rq_ray r = random_ray(&rng);
    rq_ray_ex all = ray_ex(r, 0xFFFFFFFFu, 0);
    rq_hit_ex h = trace_ex(open, &all);
    if (h.prim == RQ_INVALID_ID) {
      continue;
    }
    int clear = 0, front = front_of(&r, &h, &clear);
    if (!clear) {
      skipped++;
      continue;
    }
    for (int side = 0; side < 2; side++) { /* side 0 culls back faces, side 1 front faces */
      int culled = side == 0 ? !front : front;
      rq_ray_ex by_ray = ray_ex(r, 0xFFFFFFFFu, ray_flags[side]);
      rq_hit_ex g = trace_ex(by_geometry[side], &all), k = trace_ex(open, &by_ray);
      CHECKF(same_hit_ex(&g, &k), "ray %d side %d: culling by geometry and by ray differ", i, side);
      if (culled) {
        seen[side]++;
        /* The face is skipped: the answer lies behind it, or is a miss. */
        CHECKF(g.t >= h.t && !(g.prim == h.prim && g.geom == h.geom), "ray %d side %d: culled face still hit", i,
               side);
        if (g.prim != RQ_INVALID_ID) {
          int clear2 = 0, front2 = front_of(&r, &g, &clear2);
          CHECKF(!clear2 || front2 == (side == 0), "ray %d side %d: hit a culled face behind", i, side);
        }
      } else {
        CHECKF(same_hit_ex(&g, &h), "ray %d side %d: an unculled face changed", i, side);
      }
    }
    /* Both faces culled: nothing is ever hit. */
    rq_ray_ex both = ray_ex(r, 0xFFFFFFFFu, RQ_RAY_CULL_BACK_FACES | RQ_RAY_CULL_FRONT_FACES);
    CHECK(!rq_scene_occluded_ex(open, &both));
  }
  CHECKF(seen[0] > 100 && seen[1] > 100 && skipped < RAYS / 50, "culled back %d front %d, skipped %d", seen[0],
         seen[1], skipped);
done:
  rq_scene_free(open);
  rq_scene_free(by_geometry[0]);
  rq_scene_free(by_geometry[1]);
  free_parts(&p);
}

/* ---- filters: an alpha test on the plane -------------------------------------------------------- */

typedef struct alpha_state {
  long calls;
  long wrong_geometry;
} alpha_state;

/* Cut-out texture: the plane's even triangles are transparent. */
static bool alpha_test(void *user, const rq_ray_ex *ray, const rq_hit_ex *candidate) {
  alpha_state *st = (alpha_state *)user;
  st->calls++;
  if (candidate->geom != 1 || ray->mask == 0) {
    st->wrong_geometry++;
  }
  return candidate->prim % 2 == 1;
}

static void test_filter(int structure) {
  parts p = make_parts();
  alpha_state st = {0, 0};
  rq_scene *s = build(&p, 3, NULL, NULL, alpha_test, &st, 1, structure);
  rq_scene *open = build(&p, 3, NULL, NULL, NULL, NULL, -1, structure);
  int transparent = 0;
  uint64_t rng = 17;
  if (!s || !open) {
    goto done;
  }
  for (int i = 0; i < RAYS; i++) {
    rq_ray r = random_ray(&rng);
    rq_ray_ex x = ray_ex(r, 0xFFFFFFFFu, 0);
    rq_hit_ex h = trace_ex(s, &x), o = trace_ex(open, &x);
    CHECKF(!(h.geom == 1 && h.prim % 2 == 0), "ray %d: a transparent triangle was hit", i);
    if (o.prim != RQ_INVALID_ID && !(o.geom == 1 && o.prim % 2 == 0)) {
      CHECKF(same_hit_ex(&h, &o), "ray %d: an opaque first hit changed", i);
    } else if (o.prim != RQ_INVALID_ID) {
      transparent++;
      CHECKF(h.t >= o.t, "ray %d: the hit behind a transparent triangle is in front of it", i);
    }
  }
  /* Straight down onto the plane beyond the cube and the soup (x, y > 3.5): one plane triangle, so
   * closest and any-hit queries both see through exactly the transparent ones. */
  int through = 0, stopped = 0;
  for (int i = 0; i < 400; i++) {
    float x = rng_float(&rng, 3.55f, 5.95f), y = rng_float(&rng, 3.55f, 5.95f);
    rq_ray r = make_ray(x, y, 3.0f, 0.0f, 0.0f, -1.0f);
    rq_ray_ex down = ray_ex(r, 0xFFFFFFFFu, 0);
    rq_ray_ex all = down;
    rq_hit_ex o = trace_ex(open, &all);
    if (o.geom != 1) {
      continue; /* a soup triangle is in the way */
    }
    rq_hit_ex h = trace_ex(s, &down);
    bool occluded = rq_scene_occluded_ex(s, &down);
    if (o.prim % 2 == 0) {
      through++;
      CHECKF(!occluded && (h.prim == RQ_INVALID_ID || h.t > o.t), "down ray %d: transparent triangle blocked", i);
    } else {
      stopped++;
      CHECKF(occluded && same_hit_ex(&h, &o), "down ray %d: opaque triangle not hit", i);
    }
  }
  CHECKF(transparent > 30 && through > 50 && stopped > 50, "transparent %d, through %d, stopped %d", transparent,
         through, stopped);
  CHECKF(st.calls > 0 && st.wrong_geometry == 0, "filter calls %ld, about the wrong geometry %ld", st.calls,
         st.wrong_geometry);
done:
  rq_scene_free(s);
  rq_scene_free(open);
  free_parts(&p);
}

/* ---- batches equal single calls ----------------------------------------------------------------- */

static void test_batches(int structure) {
  parts p = make_parts();
  const uint32_t masks[3] = {1, 2, 4};
  rq_scene *s = build(&p, 3, masks, NULL, NULL, NULL, -1, structure);
  enum { N = 500 };
  rq_ray rays[N];
  rq_ray_ex rays_ex[N];
  rq_hit_ex hits[N];
  uint8_t occ[N], occ_ex[N];
  uint64_t rng = 19;
  int blocked = 0;
  if (!s) {
    free_parts(&p);
    return;
  }
  for (int i = 0; i < N; i++) {
    rays[i] = random_ray(&rng);
    rays_ex[i] = ray_ex(rays[i], (uint32_t)(i % 8), (uint32_t)(i % 3));
  }
  memset(occ, 7, sizeof occ);
  memset(occ_ex, 7, sizeof occ_ex);
  CHECK_STATUS(rq_scene_occluded_n(s, rays, occ, N), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_occluded_ex_n(s, rays_ex, occ_ex, N), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_intersect_ex_n(s, rays_ex, hits, N), RQ_STATUS_OK);
  for (int i = 0; i < N; i++) {
    CHECKF(occ[i] == (rq_scene_occluded(s, &rays[i]) ? 1 : 0), "ray %d: occluded_n %u", i, (unsigned)occ[i]);
    CHECKF(occ_ex[i] == (rq_scene_occluded_ex(s, &rays_ex[i]) ? 1 : 0), "ray %d: occluded_ex_n %u", i,
           (unsigned)occ_ex[i]);
    rq_hit_ex h = trace_ex(s, &rays_ex[i]);
    CHECKF(same_hit_ex(&h, &hits[i]), "ray %d: intersect_ex_n differs", i);
    blocked += occ_ex[i];
  }
  CHECKF(blocked > 50 && blocked < N - 50, "%d of %d blocked", blocked, N);
  CHECK_STATUS(rq_scene_occluded_n(s, NULL, NULL, 0), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_occluded_ex_n(s, NULL, NULL, 0), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_intersect_ex_n(s, NULL, NULL, 0), RQ_STATUS_OK);
  CHECK_STATUS(rq_scene_occluded_n(NULL, rays, occ, N), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_occluded_ex_n(s, NULL, occ, 1), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_intersect_ex_n(s, rays_ex, NULL, 1), RQ_STATUS_NULL_ARGUMENT);
  rq_hit_ex miss;
  CHECK(!rq_scene_intersect_ex(NULL, &rays_ex[0], &miss) && is_miss_ex(&miss));
  CHECK(!rq_scene_intersect_ex(s, NULL, &miss) && is_miss_ex(&miss));
  CHECK(!rq_scene_occluded_ex(NULL, &rays_ex[0]));
  rq_scene_free(s);
  free_parts(&p);
}

/* ---- moved vertices answer as a fresh build of the moved meshes --------------------------------- */

static void test_set_vertices(int structure) {
  parts p = make_parts();
  const uint32_t masks[3] = {1, 2, 3};
  const uint32_t flags[3] = {0, RQ_GEOMETRY_CULL_BACK_FACES, 0};
  rq_scene *s = build(&p, 3, masks, flags, NULL, NULL, -1, structure);
  if (!s) {
    free_parts(&p);
    return;
  }
  /* Move the plane (geometry 1) up and tilt it, through a strided array (xyz + one float of padding). */
  test_mesh *plane = &p.m[1];
  float *strided = (float *)malloc(plane->nv * 4 * sizeof(float));
  if (!strided) {
    exit(EXIT_FAILURE);
  }
  for (size_t i = 0; i < plane->nv; i++) {
    float *v = &plane->v[3 * i];
    v[2] = 0.5f + 0.1f * v[0] - 0.05f * v[1];
    memcpy(&strided[4 * i], v, 3 * sizeof(float));
    strided[4 * i + 3] = NAN; /* padding: never read */
  }
  CHECK_STATUS(rq_scene_set_vertices(s, 1, strided, 4 * sizeof(float)), RQ_STATUS_OK);
  rq_scene *fresh = build(&p, 3, masks, flags, NULL, NULL, -1, structure);
  if (fresh) {
    rq_scene_report a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    a.struct_size = b.struct_size = sizeof a;
    CHECK_STATUS(rq_scene_report_get(s, &a), RQ_STATUS_OK);
    CHECK_STATUS(rq_scene_report_get(fresh, &b), RQ_STATUS_OK);
    CHECK(a.structure == b.structure && a.geometry_count == 3 && a.memory_bytes == b.memory_bytes);
    uint64_t rng = 23;
    for (int i = 0; i < RAYS; i++) {
      rq_ray r = random_ray(&rng);
      rq_ray_ex x = ray_ex(r, (uint32_t)(i % 4), 0);
      rq_hit_ex got = trace_ex(s, &x), want = trace_ex(fresh, &x);
      CHECKF(same_hit_ex(&got, &want), "ray %d: moved scene geom %u prim %u t %g, fresh geom %u prim %u t %g", i,
             (unsigned)got.geom, (unsigned)got.prim, (double)got.t, (unsigned)want.geom, (unsigned)want.prim,
             (double)want.t);
    }
    /* Refusals leave the scene as it was. */
    strided[4 * 3 + 1] = INFINITY;
    CHECK_STATUS(rq_scene_set_vertices(s, 1, strided, 4 * sizeof(float)), RQ_STATUS_INVALID_MESH);
    CHECK_STATUS(rq_scene_set_vertices(s, 3, strided, 4 * sizeof(float)), RQ_STATUS_INVALID_ARGUMENT);
    CHECK_STATUS(rq_scene_set_vertices(s, 1, strided, 8), RQ_STATUS_INVALID_MESH);
    CHECK_STATUS(rq_scene_set_vertices(s, 1, NULL, 12), RQ_STATUS_NULL_ARGUMENT);
    CHECK_STATUS(rq_scene_set_vertices(NULL, 1, strided, 12), RQ_STATUS_NULL_ARGUMENT);
    rng = 23;
    for (int i = 0; i < RAYS / 4; i++) {
      rq_ray r = random_ray(&rng);
      rq_ray_ex x = ray_ex(r, (uint32_t)(i % 4), 0);
      rq_hit_ex got = trace_ex(s, &x), want = trace_ex(fresh, &x);
      CHECKF(same_hit_ex(&got, &want), "ray %d after refusals: the scene changed", i);
    }
    rq_scene_free(fresh);
  }
  free(strided);
  rq_scene_free(s);
  free_parts(&p);
}

/* ---- refusals of the build ---------------------------------------------------------------------- */

typedef struct last_error {
  rq_status status;
  char message[256];
} last_error;

static void remember(void *user, rq_status status, const char *message) {
  last_error *e = (last_error *)user;
  e->status = status;
  snprintf(e->message, sizeof e->message, "%s", message);
}

static void test_refusals(void) {
  parts p = make_parts();
  rq_geometry_desc d[3];
  for (int g = 0; g < 3; g++) {
    rq_geometry_desc_init(&d[g]);
    d[g].mesh = mesh_desc(&p.m[g]);
  }
  CHECK(d[0].struct_size == sizeof d[0] && d[0].mask == 0xFFFFFFFFu && d[0].flags == 0 && d[0].filter == NULL);
  last_error e = {RQ_STATUS_OK, ""};
  rq_build_options o;
  rq_build_options_init(&o);
  o.on_error = remember;
  o.user = &e;
  rq_scene *s = (rq_scene *)test_sentinel();
  /* A bad index in geometry 1: refused, and the message names the geometry. */
  uint32_t saved = p.m[1].idx[4];
  p.m[1].idx[4] = 100000;
  CHECK_STATUS(rq_scene_build_geometries(d, 3, &o, NULL, &s), RQ_STATUS_INVALID_MESH);
  CHECKF(strstr(e.message, "geometry 1") != NULL, "message: %s", e.message);
  p.m[1].idx[4] = saved;
  CHECK(s == (rq_scene *)test_sentinel());
  d[2].flags = 4;
  CHECK_STATUS(rq_scene_build_geometries(d, 3, &o, NULL, &s), RQ_STATUS_INVALID_ARGUMENT);
  d[2].flags = 0;
  d[1].struct_size = 8;
  CHECK_STATUS(rq_scene_build_geometries(d, 3, &o, NULL, &s), RQ_STATUS_INVALID_ARGUMENT);
  d[1].struct_size = sizeof d[1];
  CHECK_STATUS(rq_scene_build_geometries(NULL, 3, &o, NULL, &s), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_scene_build_geometries(d, 3, &o, NULL, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK(s == (rq_scene *)test_sentinel());
  /* No geometries: an empty scene that hits nothing. */
  CHECK_STATUS(rq_scene_build_geometries(NULL, 0, NULL, NULL, &s), RQ_STATUS_OK);
  if (s != (rq_scene *)test_sentinel()) {
    rq_ray_ex x = ray_ex(make_ray(0, 0, 5, 0, 0, -1), 0xFFFFFFFFu, 0);
    CHECK(!rq_scene_occluded_ex(s, &x));
    rq_scene_free(s);
  }
  /* A scene of one mesh is geometry 0 seen by every mask but 0. */
  rq_mesh_desc md = mesh_desc(&p.m[0]);
  s = NULL;
  CHECK_STATUS(rq_scene_build(&md, NULL, NULL, &s), RQ_STATUS_OK);
  if (s) {
    rq_ray_ex x = ray_ex(make_ray(0.1f, 0.2f, 5, 0, 0, -1), 1, 0);
    rq_hit_ex h = trace_ex(s, &x);
    CHECK(h.geom == 0 && h.prim != RQ_INVALID_ID);
    x.mask = 0;
    CHECK(!rq_scene_occluded_ex(s, &x));
    rq_scene_free(s);
  }
  free_parts(&p);
}

int main(void) {
  for (size_t i = 0; i < sizeof structures / sizeof structures[0]; i++) {
    long before = test_failures;
    test_ids(structures[i]);
    test_masks(structures[i]);
    test_culling(structures[i]);
    test_filter(structures[i]);
    test_batches(structures[i]);
    test_set_vertices(structures[i]);
    printf("geometries with %s: %ld failures\n", structure_name(structures[i]), test_failures - before);
  }
  test_refusals();
  return test_finish("geometries");
}
