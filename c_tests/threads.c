/* threads.c: a scene is immutable after build and may be queried from many threads at once; every
 * thread gets exactly the answers a single thread gets. (POSIX threads; elsewhere the test only runs
 * the single-threaded part.) */
#include "common.h" /* first: it selects the POSIX declarations */

#if defined(__unix__) || defined(__APPLE__)
#include <pthread.h>
#define HAVE_PTHREADS 1
#endif

#define THREADS 4
#define RAYS 4000

typedef struct job {
  const rq_scene *scene;
  const rq_ray *rays;
  rq_hit hits[RAYS];
  int occluded_mismatches;
  int batch_status_failures;
} job;

static void *run(void *arg) {
  job *j = (job *)arg;
  /* Alternate single calls, batches and occlusion queries so that they overlap between threads. */
  for (int round = 0; round < 3; round++) {
    for (int i = 0; i < RAYS; i++) {
      rq_scene_intersect(j->scene, &j->rays[i], &j->hits[i]);
      if (rq_scene_occluded(j->scene, &j->rays[i]) != (j->hits[i].prim != RQ_INVALID_ID)) {
        j->occluded_mismatches++;
      }
    }
    rq_hit tmp[64];
    for (int i = 0; i + 64 <= RAYS; i += 64) {
      if (rq_scene_intersect_n(j->scene, j->rays + i, tmp, 64) != RQ_STATUS_OK ||
          memcmp(tmp, j->hits + i, sizeof tmp) != 0) {
        j->batch_status_failures++;
      }
    }
  }
  return NULL;
}

int main(void) {
  test_mesh m = mesh_soup(77, 2000);
  rq_scene *scene = test_build(&m, -1);
  if (!scene) {
    mesh_free(&m);
    return test_finish("threads");
  }
  static rq_ray rays[RAYS];
  uint64_t rng = 2;
  for (int i = 0; i < RAYS; i++) {
    rays[i] = make_ray(rng_float(&rng, -4, 4), rng_float(&rng, -4, 4), rng_float(&rng, -4, 4), 0, 0, 0);
    rng_dir(&rng, rays[i].dir);
  }
  static rq_hit expected[RAYS];
  CHECK_STATUS(rq_scene_intersect_n(scene, rays, expected, RAYS), RQ_STATUS_OK);
  int hits = 0;
  for (int i = 0; i < RAYS; i++) {
    hits += expected[i].prim != RQ_INVALID_ID;
  }
  CHECKF(hits > RAYS / 10, "only %d rays hit", hits);

  static job jobs[THREADS];
  for (int t = 0; t < THREADS; t++) {
    jobs[t].scene = scene;
    jobs[t].rays = rays;
  }
#if defined(HAVE_PTHREADS)
  pthread_t tid[THREADS];
  int started[THREADS];
  for (int t = 0; t < THREADS; t++) {
    started[t] = pthread_create(&tid[t], NULL, run, &jobs[t]) == 0;
    CHECKF(started[t], "pthread_create %d failed", t);
  }
  for (int t = 0; t < THREADS; t++) {
    if (started[t]) {
      CHECK(pthread_join(tid[t], NULL) == 0);
    } else {
      run(&jobs[t]);
    }
  }
#else
  for (int t = 0; t < THREADS; t++) {
    run(&jobs[t]);
  }
#endif
  for (int t = 0; t < THREADS; t++) {
    CHECKF(memcmp(jobs[t].hits, expected, sizeof expected) == 0, "thread %d saw different hits", t);
    CHECKF(jobs[t].occluded_mismatches == 0, "thread %d: %d occluded mismatches", t, jobs[t].occluded_mismatches);
    CHECKF(jobs[t].batch_status_failures == 0, "thread %d: %d batch failures", t, jobs[t].batch_status_failures);
  }
  rq_scene_free(scene);
  mesh_free(&m);
  return test_finish("threads");
}
