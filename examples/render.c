/* render.c: renders an OBJ file to a PPM image with one primary ray per pixel, shaded by the
 * geometric normal under a headlight. It follows minimal.c (read that first) and adds: loading a mesh
 * with the OBJ helper, a camera framed from the mesh's bounds, tracing rows of rays with
 * rq_scene_intersect_n, telling the scene how the ray budget is going with rq_scene_update, and
 * printing timings and the scene report.
 *
 * Build the C library with the OBJ helper, then compile with RQ_WITH_OBJ defined (repository root):
 *
 *   cargo rustc --release --lib --crate-type staticlib --features capi,obj
 *   cc -std=c99 -O2 -Wall -Wextra -DRQ_WITH_OBJ -Iinclude examples/render.c \
 *      target/release/librayq.a -lm -lpthread -ldl -lgcc_s -o render
 *   ./render scenes/teapot.obj teapot.ppm 640 480 auto
 *
 * Usage: render SCENE.obj OUT.ppm [width height] [auto|grid|kdtree]
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
#error "render.c uses the OBJ helper: compile with -DRQ_WITH_OBJ and link a library built with --features capi,obj"
#endif

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

/* The enum name of a status, for messages a user can search the header for. */
static const char *status_name(rq_status s) {
  switch (s) {
  case RQ_STATUS_OK: return "RQ_STATUS_OK";
  case RQ_STATUS_NULL_ARGUMENT: return "RQ_STATUS_NULL_ARGUMENT";
  case RQ_STATUS_INVALID_ARGUMENT: return "RQ_STATUS_INVALID_ARGUMENT";
  case RQ_STATUS_INVALID_MESH: return "RQ_STATUS_INVALID_MESH";
  case RQ_STATUS_ABI_MISMATCH: return "RQ_STATUS_ABI_MISMATCH";
  case RQ_STATUS_INVALID_OPERATION: return "RQ_STATUS_INVALID_OPERATION";
  case RQ_STATUS_UNSUPPORTED: return "RQ_STATUS_UNSUPPORTED";
  case RQ_STATUS_OUT_OF_MEMORY: return "RQ_STATUS_OUT_OF_MEMORY";
  case RQ_STATUS_MEMORY_LIMIT: return "RQ_STATUS_MEMORY_LIMIT";
  case RQ_STATUS_CANCELLED: return "RQ_STATUS_CANCELLED";
  case RQ_STATUS_OBJ_UNREADABLE: return "RQ_STATUS_OBJ_UNREADABLE";
  case RQ_STATUS_OBJ_MALFORMED: return "RQ_STATUS_OBJ_MALFORMED";
  case RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE: return "RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE";
  case RQ_STATUS_PANIC: return "RQ_STATUS_PANIC";
  case RQ_STATUS_INTERNAL: return "RQ_STATUS_INTERNAL";
  default: return "RQ_STATUS_(other)";
  }
}

/* on_error for rq_obj_load_ex: the message names the file and the line ("teapot.obj:12: ..."). */
static void print_obj_error(void *user, rq_status status, const char *message) {
  (void)user;
  (void)status;
  fprintf(stderr, "render: %s\n", message);
}

static int report_failure(const char *what, rq_status s) {
  fprintf(stderr, "render: %s failed: %s (%s, %u)\n", what, rq_status_str(s), status_name(s), (unsigned)s);
  return EXIT_FAILURE;
}

static const char *outcome_name(rq_outcome o) {
  switch (o) {
  case RQ_OUTCOME_FORCED: return "forced";
  case RQ_OUTCOME_GRID_FASTER_PER_RAY: return "grid faster per ray";
  case RQ_OUTCOME_BELOW_BREAK_EVEN: return "below break-even";
  case RQ_OUTCOME_ABOVE_BREAK_EVEN: return "above break-even";
  case RQ_OUTCOME_ONLINE_ON_GRID: return "online, on the grid";
  case RQ_OUTCOME_ONLINE_SWITCHED: return "online, switched to the kd-tree";
  default: return "unknown";
  }
}

static int usage(void) {
  fprintf(stderr, "usage: render SCENE.obj OUT.ppm [width height] [auto|grid|kdtree]\n"
                  "  width and height in 1..16384 (default 512 x 512); structure default auto\n");
  return 2;
}

/* A whole-string positive integer in [1, 16384], or 0. */
static int parse_size(const char *s) {
  char *end = NULL;
  errno = 0;
  long v = strtol(s, &end, 10);
  if (errno != 0 || end == s || *end != '\0' || v < 1 || v > 16384) {
    return 0;
  }
  return (int)v;
}

/* AUTO, GRID or KDTREE from a name, or -1. */
static int parse_structure(const char *s) {
  if (strcmp(s, "auto") == 0) return RQ_STRUCTURE_AUTO;
  if (strcmp(s, "grid") == 0) return RQ_STRUCTURE_GRID;
  if (strcmp(s, "kdtree") == 0) return RQ_STRUCTURE_KDTREE;
  return -1;
}

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
static float dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static vec3 cross(vec3 a, vec3 b) { return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x); }
static vec3 normalize(vec3 a) {
  float l = sqrtf(dot(a, a));
  return l > 0.0f ? scale(a, 1.0f / l) : a;
}

/* Vertex `i` of a mesh description (xyz at the start of each `vertex_stride`-byte record). */
static vec3 mesh_vertex(const rq_mesh_desc *m, uint32_t i) {
  float p[3];
  memcpy(p, (const unsigned char *)m->vertices + (size_t)i * m->vertex_stride, sizeof p);
  return v3(p[0], p[1], p[2]);
}

static unsigned char to_byte(float linear) {
  float c = linear <= 0.0f ? 0.0f : linear >= 1.0f ? 1.0f : powf(linear, 1.0f / 2.2f);
  return (unsigned char)(c * 255.0f + 0.5f);
}

/* ---- the program --------------------------------------------------------------------------------- */

int main(int argc, char **argv) {
  int width = 512, height = 512, structure = RQ_STRUCTURE_AUTO;
  if (argc < 3 || argc > 6) {
    return usage();
  }
  if (argc == 4 || argc == 6) {
    structure = parse_structure(argv[argc - 1]);
    if (structure < 0) {
      return usage();
    }
  }
  if (argc >= 5) {
    width = parse_size(argv[3]);
    height = parse_size(argv[4]);
    if (!width || !height) {
      return usage();
    }
  }
  const char *scene_path = argv[1], *out_path = argv[2];

  int exit_code = EXIT_FAILURE;
  rq_obj *obj = NULL;
  rq_scene *scene = NULL;
  rq_ray *rays = NULL;
  rq_hit *hits = NULL;
  unsigned char *image = NULL;
  FILE *out = NULL;
  rq_status s;

  /* 1. Load the OBJ (all objects merged, polygons fanned into triangles) and describe it. The
   *    description points into the rq_obj, so it is valid until rq_obj_free. A refused file is
   *    explained through on_error, which names the file and the line. */
  rq_obj_load_options load_options;
  rq_obj_load_options_init(&load_options);
  load_options.on_error = print_obj_error;
  s = rq_obj_load_ex(scene_path, &load_options, &obj);
  if (s != RQ_STATUS_OK) {
    exit_code = report_failure("rq_obj_load_ex", s);
    goto done;
  }
  rq_mesh_desc mesh;
  float lo[3], hi[3];
  if ((s = rq_obj_mesh_desc(obj, &mesh)) != RQ_STATUS_OK) {
    exit_code = report_failure("rq_obj_mesh_desc", s);
    goto done;
  }
  if ((s = rq_obj_bounds(obj, lo, hi)) != RQ_STATUS_OK) {
    exit_code = report_failure("rq_obj_bounds (is the file empty?)", s);
    goto done;
  }
  printf("%s: %zu vertices, %zu triangles\n", scene_path, mesh.vertex_count, mesh.triangle_count);

  /* 2. Build the scene. We know the budget exactly: one ray per pixel. */
  rq_build_options options;
  rq_build_options_init(&options);
  options.structure = (rq_structure)structure;
  options.expected_rays = (uint64_t)width * (uint64_t)height;
  double t0 = now_seconds();
  s = rq_scene_build(&mesh, &options, NULL, &scene);
  double build_seconds = now_seconds() - t0;
  if (s != RQ_STATUS_OK) {
    exit_code = report_failure("rq_scene_build", s);
    goto done;
  }

  /* 3. A camera looking at the centre of the bounds from the front-right, above (a product shot),
   *    at a distance where the box's bounding sphere about fills the shorter side of the image. */
  vec3 bmin = v3(lo[0], lo[1], lo[2]), bmax = v3(hi[0], hi[1], hi[2]);
  vec3 centre = scale(add(bmin, bmax), 0.5f);
  float radius = 0.5f * sqrtf(dot(sub(bmax, bmin), sub(bmax, bmin)));
  if (!(radius > 0.0f)) {
    radius = 1.0f;
  }
  const float fov_y = 35.0f * 3.14159265f / 180.0f, tan_half = tanf(0.5f * fov_y);
  const float aspect = (float)width / (float)height;
  vec3 back = normalize(v3(1.0f, 0.75f, 1.6f)); /* from the centre towards the eye; y is up */
  const float half_fov = aspect < 1.0f ? atanf(tan_half * aspect) : 0.5f * fov_y;
  vec3 eye = add(centre, scale(back, 0.8f * radius / sinf(half_fov)));
  vec3 forward = normalize(sub(centre, eye));
  vec3 right = normalize(cross(forward, v3(0.0f, 1.0f, 0.0f)));
  vec3 up = cross(right, forward);

  /* 4. Trace row by row: fill a row of rays, hand them to rq_scene_intersect_n, shade the hits. */
  rays = (rq_ray *)malloc((size_t)width * sizeof *rays);
  hits = (rq_hit *)malloc((size_t)width * sizeof *hits);
  image = (unsigned char *)malloc((size_t)width * (size_t)height * 3);
  if (!rays || !hits || !image) {
    fprintf(stderr, "render: out of memory\n");
    goto done;
  }
  double ray_seconds = 0.0;
  uint64_t total = (uint64_t)width * (uint64_t)height, traced = 0, hit_count = 0;
  for (int y = 0; y < height; y++) {
    float sy = (1.0f - 2.0f * ((float)y + 0.5f) / (float)height) * tan_half;
    for (int x = 0; x < width; x++) {
      float sx = (2.0f * ((float)x + 0.5f) / (float)width - 1.0f) * tan_half * aspect;
      vec3 d = add(forward, add(scale(right, sx), scale(up, sy)));
      rq_ray *r = &rays[x];
      r->org[0] = eye.x;
      r->org[1] = eye.y;
      r->org[2] = eye.z;
      r->dir[0] = d.x;
      r->dir[1] = d.y;
      r->dir[2] = d.z;
      r->tmin = 0.0f;
      r->tmax = INFINITY;
    }
    double r0 = now_seconds();
    s = rq_scene_intersect_n(scene, rays, hits, (size_t)width);
    ray_seconds += now_seconds() - r0;
    if (s != RQ_STATUS_OK) {
      exit_code = report_failure("rq_scene_intersect_n", s);
      goto done;
    }
    traced += (uint64_t)width;
    /* Between batches, tell the scene how the budget is going (it may switch structures here). */
    if ((s = rq_scene_update(scene, (uint64_t)width, total - traced)) != RQ_STATUS_OK) {
      exit_code = report_failure("rq_scene_update", s);
      goto done;
    }
    for (int x = 0; x < width; x++) {
      unsigned char *px = &image[3 * ((size_t)y * (size_t)width + (size_t)x)];
      float c[3];
      if (hits[x].prim != RQ_INVALID_ID) {
        /* Geometric normal from the triangle's vertices; a headlight makes it two-sided Lambert. */
        const uint32_t *tri = &mesh.indices[3 * (size_t)hits[x].prim];
        vec3 p0 = mesh_vertex(&mesh, tri[0]), p1 = mesh_vertex(&mesh, tri[1]), p2 = mesh_vertex(&mesh, tri[2]);
        vec3 n = normalize(cross(sub(p1, p0), sub(p2, p0)));
        vec3 d = normalize(v3(rays[x].dir[0], rays[x].dir[1], rays[x].dir[2]));
        float lambert = fabsf(dot(n, d));
        float k = 0.08f + 0.92f * lambert;
        c[0] = 0.90f * k;
        c[1] = 0.72f * k;
        c[2] = 0.45f * k;
        hit_count++;
      } else {
        /* A vertical gradient behind the object. */
        float t = (float)y / (float)(height > 1 ? height - 1 : 1);
        c[0] = 0.10f + 0.10f * t;
        c[1] = 0.12f + 0.10f * t;
        c[2] = 0.18f + 0.12f * t;
      }
      px[0] = to_byte(c[0]);
      px[1] = to_byte(c[1]);
      px[2] = to_byte(c[2]);
    }
  }

  /* 5. Write a binary PPM: a text header, then width * height RGB bytes, top row first. */
  out = fopen(out_path, "wb");
  if (!out) {
    fprintf(stderr, "render: cannot write %s\n", out_path);
    goto done;
  }
  fprintf(out, "P6\n%d %d\n255\n", width, height);
  if (fwrite(image, 3, (size_t)width * (size_t)height, out) != (size_t)width * (size_t)height) {
    fprintf(stderr, "render: short write to %s\n", out_path);
    goto done;
  }
  if (fclose(out) != 0) {
    out = NULL;
    fprintf(stderr, "render: cannot finish %s\n", out_path);
    goto done;
  }
  out = NULL;

  /* 6. What happened. */
  rq_scene_report report;
  report.struct_size = sizeof report;
  if ((s = rq_scene_report_get(scene, &report)) != RQ_STATUS_OK) {
    exit_code = report_failure("rq_scene_report_get", s);
    goto done;
  }
  printf("image: %d x %d, %llu of %llu rays hit, written to %s\n", width, height, (unsigned long long)hit_count,
         (unsigned long long)total, out_path);
  printf("build: %.3f ms\n", build_seconds * 1e3);
  printf("rays:  %.3f ms, %.2f M rays/s\n", ray_seconds * 1e3,
         ray_seconds > 0.0 ? (double)total / ray_seconds * 1e-6 : 0.0);
  printf("scene: structure %s (%s), %zu triangles, grid %u x %u x %u, memory %zu bytes (%.2f MiB)\n",
         report.structure == RQ_STRUCTURE_KDTREE ? "kd-tree" : "grid", outcome_name(report.outcome),
         report.triangle_count, (unsigned)report.grid_resolution[0], (unsigned)report.grid_resolution[1],
         (unsigned)report.grid_resolution[2], report.memory_bytes, (double)report.memory_bytes / (1024.0 * 1024.0));
  if (!isnan(report.break_even_rays)) {
    printf("selector: break-even %.3g rays, expected %llu\n", report.break_even_rays,
           (unsigned long long)report.expected_rays);
  }
  exit_code = EXIT_SUCCESS;

done:
  /* 7. Free everything (every _free accepts NULL). The scene copied the mesh, so the order is free. */
  if (out) {
    fclose(out);
  }
  free(image);
  free(hits);
  free(rays);
  rq_scene_free(scene);
  rq_obj_free(obj);
  return exit_code;
}
