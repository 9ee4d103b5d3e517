/* pathtrace.c: a small diffuse path tracer on rayq, and the application the library is built for
 * (Hapala, Karlik, Havran 2011): a renderer that picks the acceleration structure by its ray budget.
 * A uniform grid builds fast but traces slowly; a SAH kd-tree builds slowly but traces fast. Past a
 * break-even number of rays W* the kd-tree pays for its build. The program shows the four ways to use
 * that from C:
 *
 *   --budget known    count the rays up front (width * height * spp * (1 + bounces), an upper bound)
 *                     and pass it as rq_build_options.expected_rays with RQ_STRUCTURE_AUTO: the
 *                     selector builds the grid or the kd-tree; after every pass the program tells
 *                     the scene the rays traced and those that may remain, so that a kd-tree chosen
 *                     on the library's own sample rays is checked once on this program's rays (it
 *                     may go back to the grid: outcome GRID_FASTER_PER_RAY).
 *   --budget unknown  expected_rays = 0: the scene starts on the grid; after every pass (one sample
 *                     per pixel) the program tells it how many rays it traced with rq_scene_update,
 *                     and the scene switches to the kd-tree once the time lost on the grid reaches
 *                     the kd-tree's estimated build time (the outcome becomes ONLINE_SWITCHED).
 *   --budget grid     force the grid.
 *   --budget kdtree   force the kd-tree.
 *
 * The scene has two geometries (rq_scene_build_geometries): the OBJ mesh (geometry 0, a warm
 * material) and a ground square below it (geometry 1, a grey checker); the shader picks the material
 * by rq_hit_ex.geom and takes the geometric normal from rq_hit_ex.ng. Rendering: per sample, a
 * jittered camera ray, then up to MAX_BOUNCES diffuse bounces (cosine-weighted about the normal
 * turned towards the ray); at every hit a shadow ray towards the sun (next-event estimation), and rays
 * that escape see a sky. Rays are traced as a wavefront: all primary rays of a pass in one
 * rq_scene_intersect_ex_n call, all their shadow rays in one rq_scene_occluded_n call, then all
 * surviving first bounces, and so on. The random numbers depend only on (pixel, pass, bounce), and
 * rayq's hits are exact (ties go to the lowest (geometry, triangle)), so every --budget mode writes
 * the same image.
 *
 * Build (repository root; the OBJ helper needs --features obj and -DRQ_WITH_OBJ):
 *
 *   cargo rustc --release --lib --crate-type staticlib --features capi,obj
 *   gcc -std=c99 -O2 -Wall -Wextra -Wpedantic -DRQ_WITH_OBJ -Iinclude examples/pathtrace.c \
 *       target/release/librayq.a -lm -lpthread -ldl -lgcc_s -o pathtrace
 *   ./pathtrace scenes/teapot.obj teapot.ppm 256 192 16 --budget unknown
 *
 * Usage: pathtrace SCENE.obj OUT.ppm [width height spp] [--budget known|unknown|grid|kdtree]
 */
#if defined(__unix__) || defined(__APPLE__)
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#endif

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rayq.h"

#if !defined(RQ_WITH_OBJ)
#error "pathtrace.c uses the OBJ helper: compile with -DRQ_WITH_OBJ and link a library built with --features capi,obj"
#endif

#define MAX_BOUNCES 2      /* diffuse bounces after the camera ray */
#define SUN 2.0f           /* irradiance from the sun on a surface facing it */
#define PI_F 3.14159265358979f

/* ---- small helpers ----------------------------------------------------------------------------- */

/* Wall-clock seconds (monotonic where POSIX has it). */
static double now_seconds(void) {
#if defined(CLOCK_MONOTONIC)
  struct timespec ts;
  if (clock_gettime(CLOCK_MONOTONIC, &ts) == 0) {
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
  }
#endif
  return (double)clock() / CLOCKS_PER_SEC;
}

static int fail(const char *what, rq_status s) {
  fprintf(stderr, "pathtrace: %s failed: %s (status %u)\n", what, rq_status_str(s), (unsigned)s);
  return EXIT_FAILURE;
}

static const char *outcome_name(rq_outcome o) {
  switch (o) {
  case RQ_OUTCOME_FORCED: return "FORCED";
  case RQ_OUTCOME_GRID_FASTER_PER_RAY: return "GRID_FASTER_PER_RAY";
  case RQ_OUTCOME_BELOW_BREAK_EVEN: return "BELOW_BREAK_EVEN";
  case RQ_OUTCOME_ABOVE_BREAK_EVEN: return "ABOVE_BREAK_EVEN";
  case RQ_OUTCOME_ONLINE_ON_GRID: return "ONLINE_ON_GRID";
  case RQ_OUTCOME_ONLINE_SWITCHED: return "ONLINE_SWITCHED";
  default: return "(unknown outcome)";
  }
}

static const char *structure_name(rq_structure s) {
  return s == RQ_STRUCTURE_KDTREE ? "kdtree" : s == RQ_STRUCTURE_GRID ? "grid" : "auto";
}

/* ---- arguments ----------------------------------------------------------------------------------- */

typedef enum budget_mode { BUDGET_KNOWN, BUDGET_UNKNOWN, BUDGET_GRID, BUDGET_KDTREE } budget_mode;

typedef struct args {
  const char *scene_path, *out_path;
  int width, height, spp;
  budget_mode budget;
} args;

static int usage(void) {
  fprintf(stderr, "usage: pathtrace SCENE.obj OUT.ppm [width height spp] [--budget known|unknown|grid|kdtree]\n"
                  "  width, height in 1..16384 (default 256 x 192), spp in 1..65536 (default 4), budget default known\n");
  return 2;
}

/* A whole-string integer in [1, max], or 0. */
static int parse_int(const char *s, long max) {
  char *end = NULL;
  errno = 0;
  long v = strtol(s, &end, 10);
  if (errno != 0 || end == s || *end != '\0' || v < 1 || v > max) {
    return 0;
  }
  return (int)v;
}

static int parse_budget(const char *s, budget_mode *out) {
  static const char *const names[] = {"known", "unknown", "grid", "kdtree"};
  for (int i = 0; i < 4; i++) {
    if (strcmp(s, names[i]) == 0) {
      *out = (budget_mode)i;
      return 1;
    }
  }
  return 0;
}

/* Positional SCENE OUT [w h spp]; `--budget MODE` may come anywhere after the program name. */
static int parse_args(int argc, char **argv, args *a) {
  const char *pos[5];
  int npos = 0;
  a->width = 256;
  a->height = 192;
  a->spp = 4;
  a->budget = BUDGET_KNOWN;
  for (int i = 1; i < argc; i++) {
    if (strcmp(argv[i], "--budget") == 0) {
      if (i + 1 >= argc || !parse_budget(argv[i + 1], &a->budget)) {
        return 0;
      }
      i++;
    } else if (npos < 5) {
      pos[npos++] = argv[i];
    } else {
      return 0;
    }
  }
  if (npos != 2 && npos != 5) {
    return 0;
  }
  a->scene_path = pos[0];
  a->out_path = pos[1];
  if (npos == 5) {
    a->width = parse_int(pos[2], 16384);
    a->height = parse_int(pos[3], 16384);
    a->spp = parse_int(pos[4], 65536);
    if (!a->width || !a->height || !a->spp) {
      return 0;
    }
  }
  return 1;
}

/* ---- vectors ------------------------------------------------------------------------------------- */

typedef struct vec3 {
  float x, y, z;
} vec3;

static vec3 v3(float x, float y, float z) {
  vec3 r;
  r.x = x;
  r.y = y;
  r.z = z;
  return r;
}
static vec3 add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static vec3 sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static vec3 scale(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static vec3 mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static float dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static vec3 cross(vec3 a, vec3 b) { return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x); }
static vec3 normalize(vec3 a) {
  float l = sqrtf(dot(a, a));
  return l > 0.0f ? scale(a, 1.0f / l) : a;
}

static vec3 ray_ex_org(const rq_ray_ex *r) { return v3(r->org[0], r->org[1], r->org[2]); }
static vec3 ray_ex_dir(const rq_ray_ex *r) { return v3(r->dir[0], r->dir[1], r->dir[2]); }

/* A plain ray (the shadow rays). */
static void set_shadow_ray(rq_ray *r, vec3 org, vec3 dir, float tmin) {
  r->org[0] = org.x;
  r->org[1] = org.y;
  r->org[2] = org.z;
  r->tmin = tmin;
  r->dir[0] = dir.x;
  r->dir[1] = dir.y;
  r->dir[2] = dir.z;
  r->tmax = INFINITY;
}

/* A ray that sees every geometry and both faces. */
static void set_ray(rq_ray_ex *r, vec3 org, vec3 dir, float tmin) {
  rq_ray plain;
  set_shadow_ray(&plain, org, dir, tmin);
  memcpy(r->org, plain.org, sizeof r->org);
  memcpy(r->dir, plain.dir, sizeof r->dir);
  r->tmin = plain.tmin;
  r->tmax = plain.tmax;
  r->mask = 0xFFFFFFFFu;
  r->flags = 0;
}

/* The hit's unit geometric normal (rq_hit_ex.ng), turned to face against `dir` (two-sided surfaces:
 * OBJ winding is not reliable). */
static vec3 facing_normal(const rq_hit_ex *h, vec3 dir) {
  vec3 n = normalize(v3(h->ng[0], h->ng[1], h->ng[2]));
  return dot(n, dir) > 0.0f ? scale(n, -1.0f) : n;
}

/* ---- random numbers ------------------------------------------------------------------------------ */

/* splitmix64: one 64-bit state, a good stream from any seed, including consecutive ones. */
static uint64_t splitmix64(uint64_t *state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/* A float in [0, 1) from the top 24 bits. */
static float rand01(uint64_t *state) { return (float)(splitmix64(state) >> 40) * (1.0f / 16777216.0f); }

/* The seed of one path: a function of pixel and pass only, so the image does not depend on the
 * structure, the batch sizes or the order of tracing. */
static uint64_t path_seed(size_t pixel, int pass) {
  uint64_t s = ((uint64_t)pixel << 20) ^ (uint64_t)pass;
  (void)splitmix64(&s);
  return s;
}

/* ---- camera, sky, and the diffuse bounce ---------------------------------------------------------- */

/* OBJ files disagree on which axis is up (teapot.obj: y, stadium_teapot.obj: z). Guess: the axis in
 * which the box is thinnest, when it is clearly thinner than the others (a landscape); else y. */
static int guess_up_axis(const float lo[3], const float hi[3]) {
  float e[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
  for (int a = 0; a < 3; a++) {
    if (2.0f * e[a] < e[(a + 1) % 3] && 2.0f * e[a] < e[(a + 2) % 3]) {
      return a;
    }
  }
  return 1;
}

/* A vector given in a y-up frame, in the world whose up axis is `up`. The axes are permuted
 * cyclically, which keeps the frame right-handed. */
static vec3 from_y_up(vec3 v, int up) {
  return up == 2 ? v3(v.z, v.x, v.y) : up == 0 ? v3(v.y, v.z, v.x) : v;
}

typedef struct camera {
  vec3 eye, forward, right, up;
  vec3 world_up; /* for the sky */
  vec3 sun;      /* unit direction towards the sun */
  int up_axis;
  float tan_half, aspect;
} camera;

/* Looks at the centre of the box from the front-right, above (as render.c does), at a distance where
 * the box's bounding sphere about fills the shorter side of the image. */
static camera make_camera(const float lo[3], const float hi[3], int width, int height) {
  camera c;
  int up_axis = guess_up_axis(lo, hi);
  c.up_axis = up_axis;
  c.world_up = from_y_up(v3(0.0f, 1.0f, 0.0f), up_axis);
  c.sun = normalize(from_y_up(v3(-0.5f, 1.0f, 0.35f), up_axis));
  vec3 bmin = v3(lo[0], lo[1], lo[2]), bmax = v3(hi[0], hi[1], hi[2]);
  vec3 centre = scale(add(bmin, bmax), 0.5f);
  float radius = 0.5f * sqrtf(dot(sub(bmax, bmin), sub(bmax, bmin)));
  if (!(radius > 0.0f)) {
    radius = 1.0f;
  }
  const float fov_y = 35.0f * PI_F / 180.0f;
  c.tan_half = tanf(0.5f * fov_y);
  c.aspect = (float)width / (float)height;
  const float half_fov = c.aspect < 1.0f ? atanf(c.tan_half * c.aspect) : 0.5f * fov_y;
  vec3 back = normalize(from_y_up(v3(1.0f, 0.75f, 1.6f), up_axis)); /* from the centre towards the eye */
  c.eye = add(centre, scale(back, 0.8f * radius / sinf(half_fov)));
  c.forward = normalize(sub(centre, c.eye));
  c.right = normalize(cross(c.forward, c.world_up));
  c.up = cross(c.right, c.forward);
  return c;
}

/* The direction through image point (px, py), in pixels from the top-left corner. */
static vec3 camera_dir(const camera *c, float px, float py, int width, int height) {
  float sx = (2.0f * px / (float)width - 1.0f) * c->tan_half * c->aspect;
  float sy = (1.0f - 2.0f * py / (float)height) * c->tan_half;
  return normalize(add(c->forward, add(scale(c->right, sx), scale(c->up, sy))));
}

/* The only light: a bright sky above, a dim ground below, so open surfaces are lit and creases and
 * undersides are dark. `dir` is a unit vector. */
static vec3 sky(vec3 dir, vec3 world_up) {
  float y = dot(dir, world_up);
  if (y >= 0.0f) {
    vec3 horizon = v3(1.0f, 1.0f, 1.0f), zenith = v3(0.45f, 0.65f, 1.0f);
    return add(scale(horizon, 1.0f - y), scale(zenith, y));
  }
  return v3(0.25f, 0.22f, 0.2f);
}

/* A cosine-weighted direction about unit n. With this density the Lambert estimator's weight is just
 * the albedo (cos / pdf = pi cancels the BRDF's 1/pi). Basis: Duff et al. 2017. */
static vec3 cosine_direction(vec3 n, uint64_t *rng) {
  float sign = n.z >= 0.0f ? 1.0f : -1.0f;
  float a = -1.0f / (sign + n.z), b = n.x * n.y * a;
  vec3 t = v3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
  vec3 bt = v3(b, sign + n.y * n.y * a, -n.y);
  float r = sqrtf(rand01(rng)), phi = 2.0f * PI_F * rand01(rng);
  float z = sqrtf(fmaxf(0.0f, 1.0f - r * r));
  return normalize(add(add(scale(t, r * cosf(phi)), scale(bt, r * sinf(phi))), scale(n, z)));
}

/* ---- the renderer -------------------------------------------------------------------------------- */

/* Per-path state of the wavefront; paths[i] belongs to rays[i] and hits[i]. */
typedef struct path {
  size_t pixel;
  vec3 throughput;
  uint64_t rng;
} path;

/* The geometries of the scene, and so the materials: rq_hit_ex.geom picks one. */
enum { GEOM_MODEL = 0, GEOM_GROUND = 1 };

typedef struct renderer {
  rq_scene *scene;
  camera cam;
  int width, height;
  float tmin;        /* ray offset off a surface: 1e-5 of the scene's diagonal */
  float checker;     /* size of the ground's checker squares */
  rq_ray_ex *rays;
  rq_hit_ex *hits;
  rq_ray *shadow;    /* shadow[i] starts at hits[i] when lit[i] says it was traced */
  uint8_t *occluded; /* 1 when shadow[i] is blocked */
  vec3 *direct;      /* what the sun adds to pixel lit_pixel[i] if shadow[i] is not blocked */
  size_t *lit_pixel;
  path *paths;
  float *accum; /* linear RGB sums, width * height * 3 */
  double trace_seconds;
} renderer;

/* The diffuse albedo at a hit: a warm colour on the model, a grey checker on the ground. */
static vec3 albedo(const renderer *r, const rq_hit_ex *h, vec3 point) {
  if (h->geom == GEOM_MODEL) {
    return v3(0.8f, 0.55f, 0.35f);
  }
  int a = (r->cam.up_axis + 1) % 3, b = (r->cam.up_axis + 2) % 3;
  float p[3] = {point.x, point.y, point.z};
  int cell = (int)floorf(p[a] / r->checker) + (int)floorf(p[b] / r->checker);
  return (cell & 1) ? v3(0.35f, 0.35f, 0.35f) : v3(0.7f, 0.7f, 0.7f);
}

/* Traces rays[0..n] (closest hits), timing only the library call. */
static rq_status trace(renderer *r, size_t n) {
  double t0 = now_seconds();
  rq_status s = rq_scene_intersect_ex_n(r->scene, r->rays, r->hits, n);
  r->trace_seconds += now_seconds() - t0;
  return s;
}

/* Traces shadow[0..n] in one batch (any hit), timing only the library call. */
static rq_status trace_shadows(renderer *r, size_t n) {
  double t0 = now_seconds();
  rq_status s = rq_scene_occluded_n(r->scene, r->shadow, r->occluded, n);
  r->trace_seconds += now_seconds() - t0;
  return s;
}

/* Shades the wavefront rays[0..n] after `trace`: escaped paths add the sky; paths that hit get a
 * shadow ray towards the sun (traced in one batch, then the sun's light added where it is not
 * blocked) and bounce (compacted to the front of the arrays) unless `last`. `*shadow_rays` receives
 * the number of shadow rays traced. Returns the number of paths that go on, or 0 with `*status` set. */
static size_t shade(renderer *r, size_t n, int last, uint64_t *shadow_rays, rq_status *status) {
  size_t lit = 0;
  for (size_t i = 0; i < n; i++) {
    const rq_hit_ex *h = &r->hits[i];
    path *p = &r->paths[i];
    vec3 dir = ray_ex_dir(&r->rays[i]);
    if (h->prim == RQ_INVALID_ID) {
      vec3 c = mul(p->throughput, sky(dir, r->cam.world_up));
      float *px = &r->accum[3 * p->pixel];
      px[0] += c.x;
      px[1] += c.y;
      px[2] += c.z;
      continue;
    }
    vec3 point = add(ray_ex_org(&r->rays[i]), scale(dir, h->t));
    vec3 n = facing_normal(h, dir);
    float cos_sun = dot(n, r->cam.sun);
    /* The sun's light reflected towards the path (albedo / pi * SUN * cos, with the pi of the cosine-
     * weighted bounces folded into SUN), if nothing blocks it. */
    if (cos_sun > 0.0f) {
      r->direct[lit] = mul(p->throughput, scale(albedo(r, h, point), SUN * cos_sun / PI_F));
      r->lit_pixel[lit] = p->pixel;
      set_shadow_ray(&r->shadow[lit], point, r->cam.sun, r->tmin);
      lit++;
    }
  }
  *status = trace_shadows(r, lit);
  if (*status != RQ_STATUS_OK) {
    return 0;
  }
  *shadow_rays = lit;
  for (size_t i = 0; i < lit; i++) {
    if (!r->occluded[i]) {
      float *px = &r->accum[3 * r->lit_pixel[i]];
      px[0] += r->direct[i].x;
      px[1] += r->direct[i].y;
      px[2] += r->direct[i].z;
    }
  }
  if (last) {
    return 0; /* out of bounces */
  }
  size_t alive = 0;
  for (size_t i = 0; i < n; i++) {
    const rq_hit_ex *h = &r->hits[i];
    if (h->prim == RQ_INVALID_ID) {
      continue;
    }
    path p = r->paths[i];
    vec3 dir = ray_ex_dir(&r->rays[i]);
    vec3 point = add(ray_ex_org(&r->rays[i]), scale(dir, h->t));
    vec3 nrm = facing_normal(h, dir);
    p.throughput = mul(p.throughput, albedo(r, h, point));
    /* The new ray starts on the surface; tmin, not an offset of the origin, keeps it off the triangle
     * it left (the same tmin on every ray keeps the hits independent of the structure). */
    set_ray(&r->rays[alive], point, cosine_direction(nrm, &p.rng), r->tmin);
    r->paths[alive] = p;
    alive++;
  }
  return alive;
}

/* One sample per pixel: the camera rays in one batch, their shadow rays in one batch, then each
 * bounce's survivors the same way. `*rays` receives the number of rays traced (shadow rays too). */
static rq_status render_pass(renderer *r, int pass, uint64_t *rays) {
  size_t n = 0;
  for (int y = 0; y < r->height; y++) {
    for (int x = 0; x < r->width; x++) {
      path *p = &r->paths[n];
      p->pixel = n;
      p->throughput = v3(1.0f, 1.0f, 1.0f);
      p->rng = path_seed(n, pass);
      float jx = rand01(&p->rng), jy = rand01(&p->rng); /* box-filtered antialiasing */
      set_ray(&r->rays[n], r->cam.eye, camera_dir(&r->cam, (float)x + jx, (float)y + jy, r->width, r->height), 0.0f);
      n++;
    }
  }
  *rays = 0;
  for (int depth = 0; depth <= MAX_BOUNCES && n > 0; depth++) {
    rq_status s = trace(r, n);
    if (s != RQ_STATUS_OK) {
      return s;
    }
    *rays += n;
    uint64_t shadow_rays = 0;
    n = shade(r, n, depth == MAX_BOUNCES, &shadow_rays, &s);
    if (s != RQ_STATUS_OK) {
      return s;
    }
    *rays += shadow_rays;
  }
  return RQ_STATUS_OK;
}

/* ---- reporting and output ------------------------------------------------------------------------ */

static rq_status get_report(const rq_scene *scene, rq_scene_report *rep) {
  rep->struct_size = sizeof *rep; /* the library fills only what this covers */
  return rq_scene_report_get(scene, rep);
}

static void print_report(const char *when, const rq_scene_report *r) {
  printf("report (%s): structure %s, outcome %s, %zu triangles, memory %zu bytes (%.2f MiB)\n", when,
         structure_name(r->structure), outcome_name(r->outcome), r->triangle_count, r->memory_bytes,
         (double)r->memory_bytes / (1024.0 * 1024.0));
  printf("  grid %u x %u x %u, kd nodes %zu, kd depth %u, refs/triangle %.2f\n", (unsigned)r->grid_resolution[0],
         (unsigned)r->grid_resolution[1], (unsigned)r->grid_resolution[2], r->kd_node_count, (unsigned)r->kd_depth,
         r->references_per_triangle);
  /* NaN estimates (a forced structure) print as "nan": the selector did not run. */
  printf("  estimated: grid %.3g s/ray, kd %.3g s/ray, kd build %.3g s, break-even W* %.4g rays; expected_rays %llu\n",
         r->grid_ray_seconds, r->kd_ray_seconds, r->kd_build_seconds, r->break_even_rays,
         (unsigned long long)r->expected_rays);
}

static unsigned char to_byte(float linear) {
  float c = linear <= 0.0f ? 0.0f : linear >= 1.0f ? 1.0f : powf(linear, 1.0f / 2.2f);
  return (unsigned char)(c * 255.0f + 0.5f);
}

/* Binary PPM (P6): a text header, then RGB bytes, top row first; the mean of `spp` samples, gamma 2.2.
 * Closes `f` in any case. */
static int write_ppm(FILE *f, const char *path, const float *accum, int width, int height, int spp) {
  size_t count = (size_t)width * (size_t)height;
  unsigned char *bytes = (unsigned char *)malloc(3 * count);
  if (!bytes) {
    fprintf(stderr, "pathtrace: out of memory for the image\n");
    fclose(f);
    return 0;
  }
  for (size_t i = 0; i < 3 * count; i++) {
    bytes[i] = to_byte(accum[i] / (float)spp);
  }
  int ok = fprintf(f, "P6\n%d %d\n255\n", width, height) > 0;
  ok = ok && fwrite(bytes, 3, count, f) == count;
  ok = (fclose(f) == 0) && ok;
  if (!ok) {
    fprintf(stderr, "pathtrace: cannot write %s: %s\n", path, strerror(errno));
  }
  free(bytes);
  return ok;
}

/* ---- the program --------------------------------------------------------------------------------- */

int main(int argc, char **argv) {
  args a;
  if (!parse_args(argc, argv, &a)) {
    return usage();
  }
  if (rq_abi_version() != RQ_ABI_VERSION) {
    fprintf(stderr, "pathtrace: rayq.h is ABI %d but the library is ABI %u\n", RQ_ABI_VERSION,
            (unsigned)rq_abi_version());
    return EXIT_FAILURE;
  }

  /* Open the output first, so that a bad path fails before the render, not after it. */
  FILE *out = fopen(a.out_path, "wb");
  if (!out) {
    fprintf(stderr, "pathtrace: cannot write %s: %s\n", a.out_path, strerror(errno));
    return EXIT_FAILURE;
  }

  int exit_code = EXIT_FAILURE;
  rq_obj *obj = NULL;
  renderer r;
  memset(&r, 0, sizeof r);
  rq_status s;

  /* 1. Load the mesh. The description points into the rq_obj and is valid until rq_obj_free; the
   *    shader reads normals from it, so the rq_obj lives as long as the scene. */
  if ((s = rq_obj_load(a.scene_path, &obj)) != RQ_STATUS_OK) {
    fprintf(stderr, "pathtrace: cannot load %s\n", a.scene_path);
    exit_code = fail("rq_obj_load", s);
    goto done;
  }
  rq_mesh_desc mesh;
  float lo[3], hi[3];
  if ((s = rq_obj_mesh_desc(obj, &mesh)) != RQ_STATUS_OK) {
    exit_code = fail("rq_obj_mesh_desc", s);
    goto done;
  }
  if ((s = rq_obj_bounds(obj, lo, hi)) != RQ_STATUS_OK) {
    exit_code = fail("rq_obj_bounds (is the mesh empty?)", s);
    goto done;
  }
  printf("%s: %zu vertices, %zu triangles; %d x %d, %d spp, up to %d bounces, budget %s\n", a.scene_path,
         mesh.vertex_count, mesh.triangle_count, a.width, a.height, a.spp, MAX_BOUNCES,
         a.budget == BUDGET_KNOWN ? "known" : a.budget == BUDGET_UNKNOWN ? "unknown"
                                          : a.budget == BUDGET_GRID  ? "grid (forced)"
                                                                     : "kdtree (forced)");

  /* 2. Build options from the budget mode. The known budget is an upper bound: every path traced to
   *    full depth with a shadow ray at every hit. Paths that escape early trace fewer, so the real
   *    count is printed at the end. */
  rq_build_options options;
  rq_build_options_init(&options);
  uint64_t pixels = (uint64_t)a.width * (uint64_t)a.height;
  switch (a.budget) {
  case BUDGET_KNOWN:
    options.structure = RQ_STRUCTURE_AUTO;
    options.expected_rays = pixels * (uint64_t)a.spp * 2 * (1 + MAX_BOUNCES);
    break;
  case BUDGET_UNKNOWN:
    options.structure = RQ_STRUCTURE_AUTO;
    options.expected_rays = 0;
    break;
  case BUDGET_GRID: options.structure = RQ_STRUCTURE_GRID; break;
  case BUDGET_KDTREE: options.structure = RQ_STRUCTURE_KDTREE; break;
  }
  /* The ground: a square below the model, three times its size, in the plane across the up axis at
   *    the bottom of its box (geometry 1; the model is geometry 0). */
  int up = guess_up_axis(lo, hi);
  float ground_v[4][3];
  const uint32_t ground_idx[6] = {0, 1, 2, 2, 1, 3};
  {
    int a1 = (up + 1) % 3, a2 = (up + 2) % 3;
    float ext = fmaxf(hi[a1] - lo[a1], hi[a2] - lo[a2]);
    for (int c = 0; c < 4; c++) {
      ground_v[c][up] = lo[up] - 1e-3f * (hi[up] - lo[up]);
      ground_v[c][a1] = 0.5f * (lo[a1] + hi[a1]) + ((c & 1) ? 1.5f : -1.5f) * ext;
      ground_v[c][a2] = 0.5f * (lo[a2] + hi[a2]) + ((c & 2) ? 1.5f : -1.5f) * ext;
    }
    r.checker = ext / 4.0f;
  }
  rq_geometry_desc geometries[2];
  rq_geometry_desc_init(&geometries[GEOM_MODEL]);
  geometries[GEOM_MODEL].mesh = mesh;
  rq_geometry_desc_init(&geometries[GEOM_GROUND]);
  geometries[GEOM_GROUND].mesh.vertices = &ground_v[0][0];
  geometries[GEOM_GROUND].mesh.vertex_count = 4;
  geometries[GEOM_GROUND].mesh.vertex_stride = sizeof ground_v[0];
  geometries[GEOM_GROUND].mesh.indices = ground_idx;
  geometries[GEOM_GROUND].mesh.triangle_count = 2;
  double t0 = now_seconds();
  s = rq_scene_build_geometries(geometries, 2, &options, NULL, &r.scene);
  double build_seconds = now_seconds() - t0;
  if (s != RQ_STATUS_OK) {
    exit_code = fail("rq_scene_build_geometries", s);
    goto done;
  }
  rq_scene_report rep;
  if ((s = get_report(r.scene, &rep)) != RQ_STATUS_OK) {
    exit_code = fail("rq_scene_report_get", s);
    goto done;
  }
  print_report("after build", &rep);
  printf("build: %.3f ms\n", build_seconds * 1e3);

  /* 3. The renderer: camera, ray offset, and wavefront arrays for one pass. */
  r.width = a.width;
  r.height = a.height;
  r.cam = make_camera(lo, hi, a.width, a.height);
  printf("camera: up axis %c (guessed from the bounds)\n", "xyz"[guess_up_axis(lo, hi)]);
  {
    vec3 diag = sub(v3(hi[0], hi[1], hi[2]), v3(lo[0], lo[1], lo[2]));
    float d = sqrtf(dot(diag, diag));
    r.tmin = 1e-5f * (d > 0.0f ? d : 1.0f);
  }
  r.rays = (rq_ray_ex *)malloc((size_t)pixels * sizeof *r.rays);
  r.hits = (rq_hit_ex *)malloc((size_t)pixels * sizeof *r.hits);
  r.shadow = (rq_ray *)malloc((size_t)pixels * sizeof *r.shadow);
  r.occluded = (uint8_t *)malloc((size_t)pixels * sizeof *r.occluded);
  r.direct = (vec3 *)malloc((size_t)pixels * sizeof *r.direct);
  r.lit_pixel = (size_t *)malloc((size_t)pixels * sizeof *r.lit_pixel);
  r.paths = (path *)malloc((size_t)pixels * sizeof *r.paths);
  r.accum = (float *)calloc((size_t)pixels * 3, sizeof *r.accum);
  if (!r.rays || !r.hits || !r.shadow || !r.occluded || !r.direct || !r.lit_pixel || !r.paths || !r.accum) {
    fprintf(stderr, "pathtrace: out of memory for %llu pixels\n", (unsigned long long)pixels);
    goto done;
  }

  /* 4. Render pass by pass. With AUTO, report each pass's rays between passes (never during a
   *    query): that is where the scene may build the kd-tree and switch to it (unknown budget), or
   *    check the kd-tree it chose on this program's own rays (known budget). */
  uint64_t total_rays = 0;
  double update_seconds = 0.0;
  double r0 = now_seconds();
  for (int pass = 0; pass < a.spp; pass++) {
    uint64_t pass_rays = 0;
    if ((s = render_pass(&r, pass, &pass_rays)) != RQ_STATUS_OK) {
      exit_code = fail("tracing", s);
      goto done;
    }
    total_rays += pass_rays;
    /* A forced structure has nothing left to decide. After the last pass no rays remain, and saying
     * so (rather than 0, "unknown") keeps the scene from building a structure no ray would use. The
     * known budget is an upper bound, so what may remain is the budget less the rays traced. */
    if (a.budget != BUDGET_UNKNOWN && a.budget != BUDGET_KNOWN) {
      continue;
    }
    uint64_t remaining = a.budget == BUDGET_UNKNOWN ? 0
                         : options.expected_rays > total_rays ? options.expected_rays - total_rays
                                                              : RQ_RAYS_REMAINING_NONE;
    rq_outcome before = rep.outcome;
    rq_structure held = rep.structure;
    double u0 = now_seconds();
    s = rq_scene_update(r.scene, pass_rays, pass + 1 == a.spp ? RQ_RAYS_REMAINING_NONE : remaining);
    double u = now_seconds() - u0;
    update_seconds += u;
    if (s != RQ_STATUS_OK) {
      exit_code = fail("rq_scene_update", s);
      goto done;
    }
    if ((s = get_report(r.scene, &rep)) != RQ_STATUS_OK) {
      exit_code = fail("rq_scene_report_get", s);
      goto done;
    }
    if (before != RQ_OUTCOME_ONLINE_SWITCHED && rep.outcome == RQ_OUTCOME_ONLINE_SWITCHED) {
      printf("pass %d/%d: switched to the kd-tree after %llu rays (W* estimate %.4g); the update took %.3f ms\n",
             pass + 1, a.spp, (unsigned long long)total_rays, rep.break_even_rays, u * 1e3);
    } else if (held == RQ_STRUCTURE_KDTREE && rep.structure == RQ_STRUCTURE_GRID) {
      printf("pass %d/%d: this program's rays took the kd-tree longer than a grid: back on the grid; the update "
             "took %.3f ms\n",
             pass + 1, a.spp, u * 1e3);
    }
  }
  double render_seconds = now_seconds() - r0;

  /* 5. The image, then what happened. */
  int written = write_ppm(out, a.out_path, r.accum, a.width, a.height, a.spp);
  out = NULL; /* closed by write_ppm */
  if (!written) {
    goto done;
  }
  if ((s = get_report(r.scene, &rep)) != RQ_STATUS_OK) {
    exit_code = fail("rq_scene_report_get", s);
    goto done;
  }
  print_report("at end", &rep);
  printf("build: %.3f ms; render: %.3f ms (tracing %.3f ms, rq_scene_update %.3f ms); wrote %s\n",
         build_seconds * 1e3, render_seconds * 1e3, r.trace_seconds * 1e3, update_seconds * 1e3, a.out_path);
  printf("rays: %llu traced (budget bound %llu); %.3f M rays/s tracing, %.3f M rays/s build+render\n",
         (unsigned long long)total_rays, (unsigned long long)(pixels * (uint64_t)a.spp * 2 * (1 + MAX_BOUNCES)),
         r.trace_seconds > 0.0 ? (double)total_rays / r.trace_seconds * 1e-6 : 0.0,
         (double)total_rays / (build_seconds + render_seconds) * 1e-6);
  exit_code = EXIT_SUCCESS;

done:
  /* 6. Free everything (every _free accepts NULL, free(NULL) is a no-op); on failure, remove the
   *    empty output rather than leave it looking like an image. */
  if (out) {
    fclose(out);
    remove(a.out_path);
  }
  free(r.accum);
  free(r.paths);
  free(r.lit_pixel);
  free(r.direct);
  free(r.occluded);
  free(r.shadow);
  free(r.hits);
  free(r.rays);
  rq_scene_free(r.scene);
  rq_obj_free(obj);
  return exit_code;
}
