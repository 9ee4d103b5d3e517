/* common.h: what every C conformance test in c_tests/ shares: a CHECK macro that prints file:line and
 * the expression and counts failures, plus small mesh builders and a deterministic random generator.
 * Everything here is static inline so a test that does not use a helper gets no warning for it. */
#ifndef RQ_TEST_COMMON_H
#define RQ_TEST_COMMON_H

/* Include this header before any other: it asks for the POSIX/BSD declarations (mmap) it uses. */
#if defined(__unix__) && !defined(_DEFAULT_SOURCE)
#define _DEFAULT_SOURCE 1
#endif

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__unix__)
#include <sys/mman.h>
#include <unistd.h>
#endif

#include "rayq.h"

/* ---- checks ------------------------------------------------------------------------------------ */

static long test_checks;
static long test_failures;

/* Failures past this many are counted but not printed, so a broken loop does not flood the log. */
#ifndef TEST_MAX_REPORTS
#define TEST_MAX_REPORTS 40
#endif

static inline int test_check(int ok, const char *file, int line, const char *expr) {
  test_checks++;
  if (ok) {
    return 1;
  }
  test_failures++;
  if (test_failures <= TEST_MAX_REPORTS) {
    fprintf(stderr, "%s:%d: CHECK failed: %s\n", file, line, expr);
  } else if (test_failures == TEST_MAX_REPORTS + 1) {
    fprintf(stderr, "(further failures are counted but not printed)\n");
  }
  return 0;
}

/* CHECK(expr): counts a failure (and prints where) when expr is false. */
#define CHECK(expr) ((void)test_check((expr) ? 1 : 0, __FILE__, __LINE__, #expr))

/* As test_check, and prints a printf-style explanation on failure. */
#if defined(__GNUC__)
__attribute__((format(printf, 5, 6)))
#endif
static inline int test_checkf(int ok, const char *file, int line, const char *expr, const char *fmt, ...) {
  if (test_check(ok, file, line, expr)) {
    return 1;
  }
  if (test_failures <= TEST_MAX_REPORTS) {
    va_list args;
    va_start(args, fmt);
    fprintf(stderr, "    ");
    vfprintf(stderr, fmt, args);
    fputc('\n', stderr);
    va_end(args);
  }
  return 0;
}

/* CHECKF(expr, fmt, ...): as CHECK, and prints a printf-style explanation on failure. */
#define CHECKF(expr, ...) ((void)test_checkf((expr) ? 1 : 0, __FILE__, __LINE__, #expr, __VA_ARGS__))

/* CHECK_STATUS(call, expected): the call returns exactly the expected status. */
#define CHECK_STATUS(call, expected) test_check_status((call), (expected), __FILE__, __LINE__, #call)

static inline void test_check_status(rq_status got, rq_status want, const char *file, int line, const char *call) {
  (void)test_checkf(got == want, file, line, call, "returned %u (%s), expected %u (%s)", (unsigned)got,
                    rq_status_str(got), (unsigned)want, rq_status_str(want));
}

/* Prints the summary line the Rust runner looks for and gives the exit status. */
static inline int test_finish(const char *name) {
  printf("%s: %ld checks, %ld failures\n", name, test_checks, test_failures);
  fflush(stdout);
  return test_failures == 0 && test_checks > 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}

/* A pointer value to pre-fill out-parameters with: compared, never dereferenced. */
static inline void *test_sentinel(void) {
  static union {
    long double ld;
    void *p;
    uint64_t u;
  } object;
  return &object;
}

/* ---- guarded memory ---------------------------------------------------------------------------- */

/* The library is Rust, which the sanitizers do not instrument: they would not see it read or write
 * past a caller's buffer. A guarded block ends exactly where an inaccessible page begins, so any such
 * access faults instead. Where mmap is missing it is a plain malloc. */
typedef struct guarded {
  unsigned char *p;    /* the caller's `size` bytes */
  unsigned char *base; /* the mapping (or the malloc block) */
  size_t total;
} guarded;

static inline guarded guarded_alloc(size_t size) {
  guarded g;
  memset(&g, 0, sizeof g);
#if defined(__unix__) && defined(MAP_ANONYMOUS)
  size_t page = (size_t)sysconf(_SC_PAGESIZE);
  size_t data = (size + page - 1) / page * page;
  g.total = data + page;
  void *base = mmap(NULL, g.total, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (base == MAP_FAILED || mprotect((unsigned char *)base + data, page, PROT_NONE) != 0) {
    fprintf(stderr, "guarded_alloc: mmap failed\n");
    exit(EXIT_FAILURE);
  }
  g.base = (unsigned char *)base;
  g.p = g.base + data - size;
#else
  g.base = (unsigned char *)malloc(size ? size : 1);
  if (!g.base) {
    exit(EXIT_FAILURE);
  }
  g.p = g.base;
#endif
  return g;
}

static inline void guarded_free(guarded *g) {
#if defined(__unix__) && defined(MAP_ANONYMOUS)
  if (g->base) {
    munmap(g->base, g->total);
  }
#else
  free(g->base);
#endif
  memset(g, 0, sizeof *g);
}

/* ---- hits and rays ----------------------------------------------------------------------------- */

static inline uint32_t float_bits(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  return u;
}

/* The exact miss of the contract: t = +INFINITY, u = v = +0, prim = RQ_INVALID_ID. */
static inline rq_hit test_miss(void) {
  rq_hit h;
  h.t = INFINITY;
  h.u = 0.0f;
  h.v = 0.0f;
  h.prim = RQ_INVALID_ID;
  return h;
}

/* Bit-for-bit equality (rq_hit has no padding: four 4-byte fields). */
static inline int same_hit(const rq_hit *a, const rq_hit *b) { return memcmp(a, b, sizeof *a) == 0; }

static inline int is_exact_miss(const rq_hit *h) {
  rq_hit m = test_miss();
  return same_hit(h, &m);
}

/* Single-call answer; also checks that occluded agrees and that a miss is the exact miss. */
static inline rq_hit trace(const rq_scene *scene, const rq_ray *r) {
  rq_hit h;
  memset(&h, 0x77, sizeof h);
  int hit = rq_scene_intersect(scene, r, &h);
  CHECK(hit == (h.prim != RQ_INVALID_ID));
  CHECK(rq_scene_occluded(scene, r) == hit);
  if (!hit) {
    CHECK(is_exact_miss(&h));
  }
  return h;
}

static inline rq_ray make_ray(float ox, float oy, float oz, float dx, float dy, float dz) {
  rq_ray r;
  r.org[0] = ox;
  r.org[1] = oy;
  r.org[2] = oz;
  r.tmin = 0.0f;
  r.dir[0] = dx;
  r.dir[1] = dy;
  r.dir[2] = dz;
  r.tmax = INFINITY;
  return r;
}

static inline void print_hit(const char *label, const rq_hit *h) {
  fprintf(stderr, "    %s: t=%a u=%a v=%a prim=%u\n", label, (double)h->t, (double)h->u, (double)h->v,
          (unsigned)h->prim);
}

/* ---- deterministic random numbers (splitmix64) ------------------------------------------------- */

static inline uint64_t rng_next(uint64_t *state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/* Uniform in [lo, hi). */
static inline float rng_float(uint64_t *state, float lo, float hi) {
  double unit = (double)(rng_next(state) >> 11) * (1.0 / 9007199254740992.0);
  return (float)(lo + (hi - lo) * unit);
}

/* A random direction, not normalized, never zero. */
static inline void rng_dir(uint64_t *state, float d[3]) {
  do {
    d[0] = rng_float(state, -1.0f, 1.0f);
    d[1] = rng_float(state, -1.0f, 1.0f);
    d[2] = rng_float(state, -1.0f, 1.0f);
  } while (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 1e-4f);
}

/* ---- meshes ------------------------------------------------------------------------------------ */

/* An indexed mesh in test memory: xyz per vertex (stride 12), three indices per triangle. */
typedef struct test_mesh {
  float *v;
  size_t nv, cap_v;
  uint32_t *idx;
  size_t nt, cap_t;
} test_mesh;

static inline void *test_grow(void *p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) {
    return p;
  }
  size_t n = *cap ? *cap * 2 : 64;
  while (n < need) {
    n *= 2;
  }
  void *q = realloc(p, n * elem);
  if (!q) {
    fprintf(stderr, "out of memory in the test itself\n");
    exit(EXIT_FAILURE);
  }
  *cap = n;
  return q;
}

static inline uint32_t mesh_vertex(test_mesh *m, float x, float y, float z) {
  m->v = (float *)test_grow(m->v, &m->cap_v, m->nv + 1, 3 * sizeof(float));
  m->v[3 * m->nv + 0] = x;
  m->v[3 * m->nv + 1] = y;
  m->v[3 * m->nv + 2] = z;
  return (uint32_t)m->nv++;
}

static inline uint32_t mesh_triangle(test_mesh *m, uint32_t a, uint32_t b, uint32_t c) {
  m->idx = (uint32_t *)test_grow(m->idx, &m->cap_t, m->nt + 1, 3 * sizeof(uint32_t));
  m->idx[3 * m->nt + 0] = a;
  m->idx[3 * m->nt + 1] = b;
  m->idx[3 * m->nt + 2] = c;
  return (uint32_t)m->nt++;
}

static inline void mesh_free(test_mesh *m) {
  free(m->v);
  free(m->idx);
  memset(m, 0, sizeof *m);
}

static inline rq_mesh_desc mesh_desc(const test_mesh *m) {
  rq_mesh_desc d;
  d.vertices = m->v;
  d.vertex_count = m->nv;
  d.vertex_stride = 3 * sizeof(float);
  d.indices = m->idx;
  d.triangle_count = m->nt;
  return d;
}

/* The closed surface of the cube [-1, 1]^3, n x n quads per face (two triangles each, diagonals
 * alternating), every lattice vertex shared between the faces that meet there. With n a power of two
 * every coordinate is exact. */
static inline test_mesh mesh_cube(int n) {
  test_mesh m;
  memset(&m, 0, sizeof m);
  size_t side = (size_t)n + 1;
  uint32_t *id = (uint32_t *)malloc(side * side * side * sizeof(uint32_t));
  if (!id) {
    exit(EXIT_FAILURE);
  }
  for (size_t i = 0; i < side * side * side; i++) {
    id[i] = RQ_INVALID_ID;
  }
  for (int axis = 0; axis < 3; axis++) {
    for (int s = 0; s <= n; s += n) {
      for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) {
          uint32_t q[4];
          int corner[4][2] = {{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}};
          for (int c = 0; c < 4; c++) {
            int l[3];
            l[axis] = s;
            l[(axis + 1) % 3] = corner[c][0];
            l[(axis + 2) % 3] = corner[c][1];
            size_t key = ((size_t)l[0] * side + (size_t)l[1]) * side + (size_t)l[2];
            if (id[key] == RQ_INVALID_ID) {
              float step = 2.0f / (float)n;
              id[key] = mesh_vertex(&m, -1.0f + step * (float)l[0], -1.0f + step * (float)l[1],
                                    -1.0f + step * (float)l[2]);
            }
            q[c] = id[key];
          }
          if ((i + j) % 2 == 0) {
            mesh_triangle(&m, q[0], q[1], q[2]);
            mesh_triangle(&m, q[0], q[2], q[3]);
          } else {
            mesh_triangle(&m, q[0], q[1], q[3]);
            mesh_triangle(&m, q[1], q[2], q[3]);
          }
        }
      }
    }
  }
  free(id);
  return m;
}

/* A Sierpinski tetrahedron: the tetrahedron of corners (1,1,1), (1,-1,-1), (-1,1,-1), (-1,-1,1)
 * replaced by four half-size copies at its corners, `depth` times; each small tetrahedron is four
 * triangles of its own four vertices (4^(depth+1) triangles). Mostly empty space around clusters:
 * a scene on which the kd-tree saves work over the grid. */
static inline void mesh_sierpinski(test_mesh *m, const float c[4][3], int depth) {
  if (depth == 0) {
    uint32_t v[4];
    for (int i = 0; i < 4; i++) {
      v[i] = mesh_vertex(m, c[i][0], c[i][1], c[i][2]);
    }
    mesh_triangle(m, v[0], v[1], v[2]);
    mesh_triangle(m, v[0], v[1], v[3]);
    mesh_triangle(m, v[0], v[2], v[3]);
    mesh_triangle(m, v[1], v[2], v[3]);
    return;
  }
  for (int k = 0; k < 4; k++) {
    float h[4][3];
    for (int i = 0; i < 4; i++) {
      for (int a = 0; a < 3; a++) {
        h[i][a] = 0.5f * (c[k][a] + c[i][a]);
      }
    }
    mesh_sierpinski(m, (const float(*)[3])h, depth - 1);
  }
}

static inline test_mesh mesh_tetra(int depth) {
  static const float corners[4][3] = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  test_mesh m;
  memset(&m, 0, sizeof m);
  mesh_sierpinski(&m, corners, depth);
  return m;
}

/* A flat n x n grid of unit quads in the plane z = 0, x and y in [0, n], shared vertices. */
static inline test_mesh mesh_plane(int n) {
  test_mesh m;
  memset(&m, 0, sizeof m);
  for (int y = 0; y <= n; y++) {
    for (int x = 0; x <= n; x++) {
      mesh_vertex(&m, (float)x, (float)y, 0.0f);
    }
  }
  for (int y = 0; y < n; y++) {
    for (int x = 0; x < n; x++) {
      uint32_t a = (uint32_t)(y * (n + 1) + x), b = a + 1, c = a + (uint32_t)n + 2, d = a + (uint32_t)n + 1;
      if ((x + y) % 2 == 0) {
        mesh_triangle(&m, a, b, c);
        mesh_triangle(&m, a, c, d);
      } else {
        mesh_triangle(&m, a, b, d);
        mesh_triangle(&m, b, c, d);
      }
    }
  }
  return m;
}

/* A soup of random triangles (sizes from tiny to large) in [-2, 2]^3, no shared vertices. */
static inline test_mesh mesh_soup(uint64_t seed, size_t count) {
  test_mesh m;
  memset(&m, 0, sizeof m);
  uint64_t s = seed;
  for (size_t i = 0; i < count; i++) {
    float c[3], size = (i % 7 == 0) ? 1.5f : (i % 3 == 0 ? 0.02f : 0.3f);
    uint32_t v[3];
    for (int k = 0; k < 3; k++) {
      c[k] = rng_float(&s, -2.0f, 2.0f);
    }
    for (int k = 0; k < 3; k++) {
      v[k] = mesh_vertex(&m, c[0] + rng_float(&s, -size, size), c[1] + rng_float(&s, -size, size),
                         c[2] + rng_float(&s, -size, size));
    }
    mesh_triangle(&m, v[0], v[1], v[2]);
  }
  return m;
}

/* Where a ray from inside the box [lo, hi] leaves it, in double from the float ray. A ray from inside
 * a closed convex mesh hits exactly there: whichever triangle it is reported on, the closest hit's t
 * is this one up to the rounding of t to float. */
static inline double exit_t(const rq_ray *r, const double lo[3], const double hi[3]) {
  double t = INFINITY;
  for (int k = 0; k < 3; k++) {
    if (r->dir[k] > 0.0f) {
      t = fmin(t, (hi[k] - (double)r->org[k]) / (double)r->dir[k]);
    } else if (r->dir[k] < 0.0f) {
      t = fmin(t, (lo[k] - (double)r->org[k]) / (double)r->dir[k]);
    }
  }
  return t;
}

/* Checks a hit of a ray from inside the box [lo, hi] against the exact exit. */
#define CHECK_EXIT(r, h, lo, hi, label, i)                                                                   \
  do {                                                                                                       \
    double te_ = exit_t(&(r), (lo), (hi));                                                                   \
    CHECKF(fabs((double)(h).t - te_) <= 1e-6 * te_,                                                          \
           "%s: ray %d hit prim %u at t %.9g but leaves the box at t %.9g\n"                                 \
           "    org (%a, %a, %a) dir (%a, %a, %a)",                                                          \
           (label), (i), (unsigned)(h).prim, (double)(h).t, te_, (double)(r).org[0], (double)(r).org[1],     \
           (double)(r).org[2], (double)(r).dir[0], (double)(r).dir[1], (double)(r).dir[2]);                 \
  } while (0)

/* Builds `m` with the given structure (NULL options when `structure` is negative: the defaults);
 * returns NULL (and reports a failure) when the build does not succeed. */
static inline rq_scene *test_build(const test_mesh *m, int structure) {
  rq_mesh_desc d = mesh_desc(m);
  rq_build_options o;
  rq_build_options_init(&o);
  if (structure >= 0) {
    o.structure = (rq_structure)structure;
  }
  rq_scene *scene = NULL;
  rq_status s = rq_scene_build(&d, structure >= 0 ? &o : NULL, NULL, &scene);
  CHECKF(s == RQ_STATUS_OK && scene != NULL, "build with structure %d: status %u (%s)", structure,
         (unsigned)s, rq_status_str(s));
  return s == RQ_STATUS_OK ? scene : NULL;
}

/* The scene's report, every field this header knows (the struct is pre-filled with 0xAB bytes, so a
 * field the library failed to write shows up as garbage rather than as a plausible zero). */
static inline rq_scene_report test_report(const rq_scene *scene) {
  rq_scene_report r;
  memset(&r, 0xAB, sizeof r);
  r.struct_size = (uint32_t)sizeof r;
  CHECK_STATUS(rq_scene_report_get(scene, &r), RQ_STATUS_OK);
  return r;
}

/* The built-in calibration blob with its eight constants replaced by `values` (in the order of the
 * blob format) and its CRC-32 recomputed; NULL (and a failure reported) if that is refused. Free with
 * rq_calibration_free. */
static inline rq_calibration *test_calibration(const double values[8]) {
  unsigned char blob[512];
  size_t len = 0;
  CHECK_STATUS(rq_calibration_to_bytes(rq_calibration_builtin(), blob, sizeof blob, &len), RQ_STATUS_OK);
  if (len < 36 + 8 * 8 + 4) {
    return NULL;
  }
  for (int i = 0; i < 8; i++) {
    uint64_t bits;
    memcpy(&bits, &values[i], 8);
    for (int b = 0; b < 8; b++) {
      blob[36 + 8 * i + b] = (unsigned char)(bits >> (8 * b)); /* little-endian, as the format says */
    }
  }
  uint32_t crc = 0xFFFFFFFFu;
  for (size_t i = 0; i + 4 < len; i++) {
    crc ^= blob[i];
    for (int k = 0; k < 8; k++) {
      crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
  }
  crc = ~crc;
  for (int b = 0; b < 4; b++) {
    blob[len - 4 + b] = (unsigned char)(crc >> (8 * b));
  }
  rq_calibration *calib = NULL;
  CHECK_STATUS(rq_calibration_from_bytes(blob, len, &calib), RQ_STATUS_OK);
  return calib;
}

#endif /* RQ_TEST_COMMON_H */
