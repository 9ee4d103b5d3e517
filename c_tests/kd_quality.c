/* kd_quality.c: rq_build_options.kd_quality. FAST builds a shallower kd-tree than DEFAULT (fewer
 * nodes), HIGH another one; every quality answers every ray bit for bit as the grid does; a value
 * outside the enum is refused, and a caller whose struct_size stops before kd_quality gets DEFAULT. */
#include "common.h"

#include <stddef.h>

static rq_scene *build_kd(const rq_mesh_desc *d, rq_kd_quality quality) {
  rq_build_options o;
  rq_build_options_init(&o);
  CHECK(o.kd_quality == RQ_KD_QUALITY_DEFAULT);
  o.structure = RQ_STRUCTURE_KDTREE;
  o.kd_quality = quality;
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(d, &o, NULL, &scene), RQ_STATUS_OK);
  return scene;
}

int main(void) {
  test_mesh mesh = mesh_soup(7, 3000);
  rq_mesh_desc d = mesh_desc(&mesh);
  rq_scene *grid = test_build(&mesh, RQ_STRUCTURE_GRID);
  const rq_kd_quality qualities[3] = {RQ_KD_QUALITY_DEFAULT, RQ_KD_QUALITY_FAST, RQ_KD_QUALITY_HIGH};
  rq_scene *kd[3] = {NULL, NULL, NULL};
  size_t nodes[3] = {0, 0, 0};
  for (int q = 0; q < 3; q++) {
    kd[q] = build_kd(&d, qualities[q]);
    if (kd[q]) {
      rq_scene_report r = test_report(kd[q]);
      CHECK(r.structure == RQ_STRUCTURE_KDTREE && r.outcome == RQ_OUTCOME_FORCED);
      nodes[q] = r.kd_node_count;
    }
  }
  if (!grid || !kd[0] || !kd[1] || !kd[2]) {
    return test_finish("kd_quality");
  }
  /* FAST prices a test at half the default's, so its SAH stops splitting sooner. */
  CHECKF(nodes[1] < nodes[0], "FAST %zu nodes, DEFAULT %zu", nodes[1], nodes[0]);
  /* HIGH sweeps every candidate plane exactly (binning otherwise): other planes, another tree. */
  CHECKF(nodes[2] != nodes[0], "HIGH %zu nodes, DEFAULT %zu", nodes[2], nodes[0]);

  /* The same answers from every quality as from the grid. */
  uint64_t rng = 5;
  for (int i = 0; i < 2000; i++) {
    float dir[3];
    rng_dir(&rng, dir);
    rq_ray r = make_ray(rng_float(&rng, -1.5f, 1.5f), rng_float(&rng, -1.5f, 1.5f), rng_float(&rng, -1.5f, 1.5f),
                        dir[0], dir[1], dir[2]);
    rq_hit want = trace(grid, &r);
    for (int q = 0; q < 3; q++) {
      rq_hit got = trace(kd[q], &r);
      CHECKF(same_hit(&got, &want), "ray %d, quality %d", i, q);
    }
  }

  /* A kd_quality outside the enum is refused; a struct_size before kd_quality reads DEFAULT. */
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = RQ_STRUCTURE_KDTREE;
  uint32_t bad = 3;
  memcpy((unsigned char *)&o + offsetof(rq_build_options, kd_quality), &bad, sizeof bad);
  rq_scene *refused = (rq_scene *)test_sentinel();
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &refused), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(refused == (rq_scene *)test_sentinel());
  o.struct_size = (uint32_t)offsetof(rq_build_options, kd_quality);
  rq_scene *older = NULL;
  CHECK_STATUS(rq_scene_build(&d, &o, NULL, &older), RQ_STATUS_OK);
  if (older) {
    CHECK(test_report(older).kd_node_count == nodes[0]);
    rq_scene_free(older);
  }

  for (int q = 0; q < 3; q++) {
    rq_scene_free(kd[q]);
  }
  rq_scene_free(grid);
  mesh_free(&mesh);
  return test_finish("kd_quality");
}
