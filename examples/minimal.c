/* minimal.c: the smallest complete rayq program. It builds a scene of one triangle, traces one ray
 * that hits it and one that misses, prints what happened, and frees everything.
 *
 * Build the C library, then compile and link this file against it (from the repository root):
 *
 *   cargo rustc --release --lib --crate-type staticlib --features capi
 *   cc -std=c99 -Wall -Wextra -Iinclude examples/minimal.c target/release/librayq.a \
 *      -lm -lpthread -ldl -lgcc_s -o minimal
 *   ./minimal
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* One header holds the whole C API. Every name in it starts with rq_ or RQ_. */
#include "rayq.h"

int main(void) {
  /* Step 0: make sure the header we compiled against matches the library we linked. The version of
   * the ABI (the layout of every struct and the meaning of every number) is a macro in the header and
   * a function in the library; a mismatch means the program was built against another rayq. */
  if (rq_abi_version() != RQ_ABI_VERSION) {
    fprintf(stderr, "rayq.h is ABI %d but the library is ABI %u\n", RQ_ABI_VERSION, (unsigned)rq_abi_version());
    return EXIT_FAILURE;
  }
  printf("%s\n", rq_version_string());

  /* Step 1: describe the geometry. rayq reads an indexed triangle mesh from the program's own memory:
   * vertex positions (three floats each, `vertex_stride` bytes apart, so xyz may sit inside a larger
   * vertex struct) and three vertex indices per triangle. Here: one triangle in the plane z = 0. */
  static const float vertices[3 * 3] = {
      0.0f, 0.0f, 0.0f, /* vertex 0 */
      1.0f, 0.0f, 0.0f, /* vertex 1 */
      0.0f, 1.0f, 0.0f, /* vertex 2 */
  };
  static const uint32_t indices[1 * 3] = {0, 1, 2}; /* triangle 0 */

  rq_mesh_desc mesh;
  mesh.vertices = vertices;
  mesh.vertex_count = 3;
  mesh.vertex_stride = 3 * sizeof(float); /* tightly packed xyz */
  mesh.indices = indices;
  mesh.triangle_count = 1;

  /* Step 2: choose build options. rq_build_options_init fills in the defaults (and the struct's size,
   * which lets newer libraries accept programs built against older headers); change what you need.
   * The default structure, AUTO, lets rayq choose between its uniform grid and its kd-tree from the
   * number of rays you expect to trace. We expect two. */
  rq_build_options options;
  rq_build_options_init(&options);
  options.expected_rays = 2;

  /* Step 3: build the scene. The build validates the mesh (finite coordinates, indices in range) and
   * copies what it needs, so `vertices` and `indices` could be freed right after. Every fallible call
   * returns an rq_status; RQ_STATUS_OK is 0, and rq_status_str explains any other value. The scene is
   * written to `scene` only on success. NULL for the calibration means the built-in one. */
  rq_scene *scene = NULL;
  rq_status status = rq_scene_build(&mesh, &options, NULL, &scene);
  if (status != RQ_STATUS_OK) {
    fprintf(stderr, "rq_scene_build failed: %s (status %u)\n", rq_status_str(status), (unsigned)status);
    return EXIT_FAILURE;
  }

  /* Step 4: describe a ray. A ray is org + t * dir for t in [tmin, tmax]; dir need not be normalized.
   * This one starts above the triangle and points straight down at (0.25, 0.25, 0). */
  rq_ray ray;
  ray.org[0] = 0.25f;
  ray.org[1] = 0.25f;
  ray.org[2] = 1.0f;
  ray.dir[0] = 0.0f;
  ray.dir[1] = 0.0f;
  ray.dir[2] = -1.0f;
  ray.tmin = 0.0f;
  ray.tmax = INFINITY; /* no upper limit */

  /* Step 5: trace it. rq_scene_intersect finds the closest hit and returns true when there is one. The
   * hit gives t (so the point is org + t * dir), the triangle's index `prim`, and the barycentric
   * weights u and v of the triangle's second and third vertex (the first vertex has 1 - u - v). */
  rq_hit hit;
  if (rq_scene_intersect(scene, &ray, &hit)) {
    printf("ray 1: hit triangle %u at t = %g, point (%g, %g, %g), u = %g, v = %g\n", (unsigned)hit.prim,
           (double)hit.t, (double)(ray.org[0] + hit.t * ray.dir[0]), (double)(ray.org[1] + hit.t * ray.dir[1]),
           (double)(ray.org[2] + hit.t * ray.dir[2]), (double)hit.u, (double)hit.v);
  } else {
    printf("ray 1: missed (unexpected)\n");
    rq_scene_free(scene);
    return EXIT_FAILURE;
  }

  /* Step 6: a ray that misses: it starts beside the triangle. On a miss the hit is still written, as
   * t = +INFINITY, u = v = 0 and prim = RQ_INVALID_ID, so code that only looks at `prim` works too. */
  ray.org[0] = 2.0f;
  ray.org[1] = 2.0f;
  if (rq_scene_intersect(scene, &ray, &hit)) {
    printf("ray 2: hit triangle %u (unexpected)\n", (unsigned)hit.prim);
    rq_scene_free(scene);
    return EXIT_FAILURE;
  }
  printf("ray 2: missed (t = %g, prim = %s)\n", (double)hit.t,
         hit.prim == RQ_INVALID_ID ? "RQ_INVALID_ID" : "a triangle?");

  /* Step 7: ask the scene what it built. The report is a growable struct too: set struct_size, and the
   * library fills in the fields it covers. */
  rq_scene_report report;
  report.struct_size = sizeof report;
  status = rq_scene_report_get(scene, &report);
  if (status != RQ_STATUS_OK) {
    fprintf(stderr, "rq_scene_report_get failed: %s\n", rq_status_str(status));
    rq_scene_free(scene);
    return EXIT_FAILURE;
  }
  printf("the scene uses the %s for %zu triangle(s) and holds %zu bytes\n",
         report.structure == RQ_STRUCTURE_KDTREE ? "kd-tree" : "uniform grid", report.triangle_count,
         report.memory_bytes);

  /* Step 8: free the scene. Every _free accepts NULL, so cleanup code need not check. A scene is
   * immutable once built: until it is freed, any number of threads may query it at once. */
  rq_scene_free(scene);
  return EXIT_SUCCESS;
}
