// consumer.cpp: a C++ program built against an installed rayq through CMake's find_package
// (docs/shipping.md; .ci/install_check builds and runs it, once linked with rayq::rayq, the static
// library, and once with rayq::rayq_shared). It builds a unit cube, shoots one ray at each face
// from outside, and exits 0 only when every ray hits the face it aims at, at the distance it must.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "rayq.h"

int main() {
  if (rq_abi_version() != RQ_ABI_VERSION) {
    std::fprintf(stderr, "consumer: rayq.h is ABI %d, the library %u\n", RQ_ABI_VERSION, rq_abi_version());
    return EXIT_FAILURE;
  }
  // The unit cube [0, 1]^3: corner i has coordinates (i & 1, i >> 1 & 1, i >> 2 & 1).
  std::vector<float> vertices;
  for (int i = 0; i < 8; i++) {
    vertices.push_back(float(i & 1));
    vertices.push_back(float(i >> 1 & 1));
    vertices.push_back(float(i >> 2 & 1));
  }
  // Two triangles per face, in the order -x, +x, -y, +y, -z, +z.
  const std::vector<uint32_t> indices = {0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3, 0, 4, 5, 0, 5, 1,
                                         2, 3, 7, 2, 7, 6, 0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5};
  rq_mesh_desc mesh = {vertices.data(), 8, 3 * sizeof(float), indices.data(), indices.size() / 3};
  rq_scene *scene = nullptr;
  rq_status s = rq_scene_build(&mesh, nullptr, nullptr, &scene);
  if (s != RQ_STATUS_OK) {
    std::fprintf(stderr, "consumer: rq_scene_build: %s\n", rq_status_str(s));
    return EXIT_FAILURE;
  }
  int failures = 0;
  for (int face = 0; face < 6; face++) {
    const int axis = face / 2;
    const float side = face % 2 ? 1.0f : -1.0f;
    // From 2 units outside the face's centre, straight at it: the face is 2 units away.
    rq_ray ray = {{0.5f, 0.5f, 0.5f}, 0.0f, {0.0f, 0.0f, 0.0f}, INFINITY};
    ray.org[axis] = 0.5f + side * 2.5f;
    ray.dir[axis] = -side;
    rq_hit hit;
    const bool ok = rq_scene_intersect(scene, &ray, &hit) && hit.prim / 2 == uint32_t(face) &&
                    std::fabs(hit.t - 2.0f) < 1e-6f;
    if (!ok) {
      std::fprintf(stderr, "consumer: face %d: prim %u t %g\n", face, hit.prim, double(hit.t));
      failures++;
    }
  }
  rq_scene_report report;
  report.struct_size = sizeof report;
  if (rq_scene_report_get(scene, &report) != RQ_STATUS_OK || report.triangle_count != 12) {
    std::fprintf(stderr, "consumer: the report is wrong\n");
    failures++;
  }
  rq_scene_free(scene);
  if (failures == 0) {
    std::printf("%s: 6 of 6 rays hit their face of the cube\n", rq_version_string());
  }
  return failures == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
