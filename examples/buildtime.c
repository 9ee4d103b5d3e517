/* buildtime.c: how long a C program waits for rq_scene_build, build after build, and how many minor
 * page faults each build took (mostly fresh pages; where the platform counts them). A renderer that
 * builds once pays the first build's figure: fresh memory, whose pages the kernel hands over one
 * fault at a time. Later builds may reuse memory the allocator kept.
 *
 *   cargo rustc --release --lib --crate-type staticlib --features capi,obj
 *   cc -std=c99 -O2 -Wall -Wextra -DRQ_WITH_OBJ -Iinclude examples/buildtime.c \
 *      target/release/librayq.a -lm -lpthread -ldl -lgcc_s -o buildtime
 *   ./buildtime scenes/teapot.obj 5 grid
 *
 * Usage: buildtime SCENE.obj [builds (1-10000, default 5)] [grid|kdtree|auto (default grid)]
 *
 * Each line: the build, the structure it made, its wall time, triangles per second and its faults.
 * docs/performance.md ("Stop 46") has what these figures showed and why.
 */
#if defined(__unix__) || defined(__APPLE__)
#define _POSIX_C_SOURCE 199309L /* clock_gettime, getrusage */
#if defined(__APPLE__)
#define _DARWIN_C_SOURCE 1 /* the fault counts of struct rusage, hidden under a strict POSIX level */
#endif
#include <sys/resource.h>
#define HAVE_RUSAGE 1
#endif

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rayq.h"

#ifndef RQ_WITH_OBJ
#error "buildtime.c uses the OBJ helper: compile with -DRQ_WITH_OBJ and link a library built with --features capi,obj"
#endif

/* Wall-clock seconds (monotonic where POSIX has it). */
static double seconds(void) {
#if defined(CLOCK_MONOTONIC)
  struct timespec t;
  if (clock_gettime(CLOCK_MONOTONIC, &t) == 0) {
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
  }
#endif
  return (double)clock() / CLOCKS_PER_SEC;
}

/* Minor page faults of the process so far, or -1 where the platform does not count them. */
static long minor_faults(void) {
#ifdef HAVE_RUSAGE
  struct rusage u;
  if (getrusage(RUSAGE_SELF, &u) == 0) return (long)u.ru_minflt;
#endif
  return -1;
}

static int usage(const char *program) {
  fprintf(stderr, "usage: %s SCENE.obj [builds (1-10000)] [grid|kdtree|auto]\n", program);
  return EXIT_FAILURE;
}

/* A build count in 1..10000, or 0 for anything else (not a number, out of range, trailing text). */
static int parse_builds(const char *s) {
  char *end = NULL;
  errno = 0;
  long v = strtol(s, &end, 10);
  if (errno != 0 || end == s || *end != '\0' || v < 1 || v > 10000) return 0;
  return (int)v;
}

static int parse_structure(const char *s) {
  if (strcmp(s, "auto") == 0) return RQ_STRUCTURE_AUTO;
  if (strcmp(s, "grid") == 0) return RQ_STRUCTURE_GRID;
  if (strcmp(s, "kdtree") == 0) return RQ_STRUCTURE_KDTREE;
  return -1;
}

int main(int argc, char **argv) {
  if (argc < 2 || argc > 4) return usage(argv[0]);
  int builds = 5;
  if (argc > 2 && (builds = parse_builds(argv[2])) == 0) return usage(argv[0]);
  int structure = RQ_STRUCTURE_GRID;
  if (argc > 3 && (structure = parse_structure(argv[3])) < 0) return usage(argv[0]);

  rq_obj *obj = NULL;
  rq_status s = rq_obj_load(argv[1], &obj);
  if (s != RQ_STATUS_OK) {
    fprintf(stderr, "rq_obj_load(%s): %s\n", argv[1], rq_status_str(s));
    return EXIT_FAILURE;
  }
  rq_mesh_desc mesh;
  if ((s = rq_obj_mesh_desc(obj, &mesh)) != RQ_STATUS_OK) {
    fprintf(stderr, "rq_obj_mesh_desc: %s\n", rq_status_str(s));
    rq_obj_free(obj);
    return EXIT_FAILURE;
  }
  rq_build_options options;
  rq_build_options_init(&options);
  options.structure = (rq_structure)structure;

  int code = EXIT_SUCCESS;
  for (int i = 0; i < builds && code == EXIT_SUCCESS; i++) {
    long f0 = minor_faults();
    double t0 = seconds();
    rq_scene *scene = NULL;
    s = rq_scene_build(&mesh, &options, NULL, &scene);
    double t = seconds() - t0;
    long f1 = minor_faults();
    if (s != RQ_STATUS_OK) {
      fprintf(stderr, "rq_scene_build: %s\n", rq_status_str(s));
      code = EXIT_FAILURE;
      break;
    }
    /* The structure the scene holds, read back (AUTO decides it). */
    rq_scene_report report;
    memset(&report, 0, sizeof report);
    report.struct_size = sizeof report;
    if ((s = rq_scene_report_get(scene, &report)) != RQ_STATUS_OK) {
      fprintf(stderr, "rq_scene_report_get: %s\n", rq_status_str(s));
      code = EXIT_FAILURE;
    } else {
      printf("build %d (%s): %.3f ms, ", i, report.structure == RQ_STRUCTURE_KDTREE ? "kd-tree" : "grid", 1e3 * t);
      if (t > 0.0) {
        printf("%.1f Mtri/s, ", (double)mesh.triangle_count / t * 1e-6);
      } else {
        printf("n/a Mtri/s, ");
      }
      if (f0 >= 0 && f1 >= 0) {
        printf("%ld page faults\n", f1 - f0);
      } else {
        printf("n/a page faults\n");
      }
    }
    rq_scene_free(scene);
  }
  rq_obj_free(obj);
  return code;
}
