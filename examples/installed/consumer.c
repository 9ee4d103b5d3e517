/* consumer.c: a C program built against an installed rayq through pkg-config, as a project that
 * vendors nothing would build it (docs/shipping.md; .ci/install_check builds and runs it):
 *
 *   cargo cinstall --profile dist --features obj --prefix "$PREFIX"
 *   export PKG_CONFIG_PATH="$(dirname "$(find "$PREFIX" -name rayq.pc)")"
 *   cc -std=c99 -DRQ_WITH_OBJ $(pkg-config --cflags rayq) consumer.c -o consumer $(pkg-config --libs rayq)
 *   ./consumer scenes/teapot.obj     (with the prefix's library directory on LD_LIBRARY_PATH)
 *
 * It loads the OBJ with the helper, builds a scene, shoots a ray at the centre of the mesh's bounds
 * from outside them, and exits 0 only when the header and library agree and the ray hits. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "rayq.h"

static void print_error(void *user, rq_status status, const char *message) {
  (void)user;
  fprintf(stderr, "consumer: %s (%s)\n", message, rq_status_str(status));
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: consumer SCENE.obj\n");
    return 2;
  }
  if (rq_abi_version() != RQ_ABI_VERSION) {
    fprintf(stderr, "consumer: rayq.h is ABI %d, the library %u\n", RQ_ABI_VERSION, (unsigned)rq_abi_version());
    return EXIT_FAILURE;
  }
  rq_obj_load_options load;
  rq_obj_load_options_init(&load);
  load.on_error = print_error;
  rq_obj *obj = NULL;
  if (rq_obj_load_ex(argv[1], &load, &obj) != RQ_STATUS_OK) {
    return EXIT_FAILURE;
  }
  int code = EXIT_FAILURE;
  rq_scene *scene = NULL;
  rq_mesh_desc mesh;
  float lo[3], hi[3];
  rq_status s = rq_obj_mesh_desc(obj, &mesh);
  if (s == RQ_STATUS_OK) {
    s = rq_obj_bounds(obj, lo, hi);
  }
  if (s == RQ_STATUS_OK) {
    s = rq_scene_build(&mesh, NULL, NULL, &scene);
  }
  if (s != RQ_STATUS_OK) {
    fprintf(stderr, "consumer: %s\n", rq_status_str(s));
    goto done;
  }
  /* From beyond the box's +x side, at the height and depth of its centre, towards -x. */
  rq_ray ray = {{hi[0] + 1.0f, 0.5f * (lo[1] + hi[1]), 0.5f * (lo[2] + hi[2])}, 0.0f, {-1.0f, 0.0f, 0.0f}, INFINITY};
  rq_hit hit;
  if (!rq_scene_intersect(scene, &ray, &hit)) {
    fprintf(stderr, "consumer: the ray through the centre missed\n");
    goto done;
  }
  printf("%s: %zu triangles; the ray hit triangle %u at t = %g\n", rq_version_string(), mesh.triangle_count,
         (unsigned)hit.prim, (double)hit.t);
  code = EXIT_SUCCESS;
done:
  rq_scene_free(scene);
  rq_obj_free(obj);
  return code;
}
