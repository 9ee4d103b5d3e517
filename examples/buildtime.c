/* buildtime.c: how long a C program waits for rq_scene_build, build after build, and how many pages
 * the process touched for the first time meanwhile (minor page faults, where the platform counts
 * them). A renderer that builds once pays the first build's figure: fresh memory, whose pages the
 * kernel hands over one fault at a time. Later builds may reuse memory the allocator kept.
 *
 *   cargo rustc --release --lib --crate-type staticlib --features capi,obj
 *   cc -std=c99 -O2 -Wall -Wextra -DRQ_WITH_OBJ -Iinclude examples/buildtime.c \
 *      target/release/librayq.a -lm -lpthread -ldl -lgcc_s -o buildtime
 *   ./buildtime ../shared/scenes/bunny.obj [builds (5)] [grid|kdtree (grid)]
 *
 * Each line: the build's wall time, triangles per second, and the minor faults it took.
 * docs/performance.md ("Stop 46") has what these figures showed and why.
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#if defined(__unix__) || defined(__APPLE__)
#include <sys/resource.h>
#define HAVE_RUSAGE 1
#endif

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

/* Minor page faults of the process so far (-1 where the platform does not count them). */
static long minor_faults(void) {
#ifdef HAVE_RUSAGE
  struct rusage u;
  if (getrusage(RUSAGE_SELF, &u) == 0) return (long)u.ru_minflt;
#endif
  return -1;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s SCENE.obj [builds] [grid|kdtree]\n", argv[0]);
    return EXIT_FAILURE;
  }
  int builds = argc > 2 ? atoi(argv[2]) : 5;
  if (builds < 1) builds = 1;
  rq_structure structure = RQ_STRUCTURE_GRID;
  if (argc > 3 && strcmp(argv[3], "kdtree") == 0) structure = RQ_STRUCTURE_KDTREE;

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
  options.structure = structure;

  int code = EXIT_SUCCESS;
  for (int i = 0; i < builds; i++) {
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
    printf("build %d: %.3f ms, %.1f Mtri/s, %ld page faults\n", i, 1e3 * t,
           (double)mesh.triangle_count / t * 1e-6, f0 < 0 ? -1L : f1 - f0);
    rq_scene_free(scene);
  }
  rq_obj_free(obj);
  return code;
}
