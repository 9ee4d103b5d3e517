/* stack_use.c: how much stack a query takes, measured by painting. A thread runs on a stack this
 * program allocated and filled with a pattern; after it has traced its rays, the lowest byte that no
 * longer holds the pattern marks the deepest the stack went. A thread that does nothing gives the
 * baseline (thread start-up), which is subtracted. Built without sanitizers (they change frames) and
 * linked with the bare-metal archive; prints "stack_use: query <bytes>" for tests/c_api.rs, which
 * compares it with its budget. */
#include "common.h"

#include <pthread.h>

#define STACK_SIZE (256 * 1024)
#define PATTERN 0xA5

typedef struct job {
  const rq_scene *scene;
  int trace;
  size_t hits;
} job;

static void *run(void *arg) {
  job *j = (job *)arg;
  if (j->trace) {
    uint64_t rng = 5;
    for (int i = 0; i < 20000; i++) {
      float dir[3];
      rng_dir(&rng, dir);
      rq_ray r = make_ray(rng_float(&rng, -3.0f, 3.0f), rng_float(&rng, -3.0f, 3.0f), rng_float(&rng, -3.0f, 3.0f),
                          dir[0], dir[1], dir[2]);
      rq_hit h;
      j->hits += rq_scene_intersect(j->scene, &r, &h);
      j->hits += rq_scene_occluded(j->scene, &r);
    }
  }
  return NULL;
}

/* Bytes of a painted stack that `j` used. */
static size_t used_by(job *j) {
  unsigned char *stack = NULL;
  if (posix_memalign((void **)&stack, 4096, STACK_SIZE) != 0) {
    CHECK(!"no memory for the stack");
    return 0;
  }
  memset(stack, PATTERN, STACK_SIZE);
  pthread_attr_t attr;
  pthread_t t;
  CHECK(pthread_attr_init(&attr) == 0);
  CHECK(pthread_attr_setstack(&attr, stack, STACK_SIZE) == 0);
  CHECK(pthread_create(&t, &attr, run, j) == 0);
  CHECK(pthread_join(t, NULL) == 0);
  pthread_attr_destroy(&attr);
  /* The stack grows down: the used part is at the top. */
  size_t untouched = 0;
  while (untouched < STACK_SIZE && stack[untouched] == PATTERN) {
    untouched++;
  }
  free(stack);
  return STACK_SIZE - untouched;
}

int main(void) {
  test_mesh m = mesh_soup(3, 20000);
  rq_mesh_desc d = mesh_desc(&m);
  size_t worst = 0;
  const rq_structure structures[] = {RQ_STRUCTURE_GRID, RQ_STRUCTURE_KDTREE};
  for (size_t i = 0; i < 2; i++) {
    rq_build_options o;
    rq_build_options_init(&o);
    o.structure = structures[i];
    rq_scene *scene = NULL;
    CHECK_STATUS(rq_scene_build(&d, &o, NULL, &scene), RQ_STATUS_OK);
    if (!scene) {
      continue;
    }
    job idle = {scene, 0, 0}, busy = {scene, 1, 0};
    size_t base = used_by(&idle), used = used_by(&busy);
    CHECKF(busy.hits > 1000, "structure %u: only %zu hits", (unsigned)structures[i], busy.hits);
    CHECKF(used > base, "structure %u: the query used no stack?", (unsigned)structures[i]);
    size_t query = used > base ? used - base : 0;
    printf("stack_use: structure %u: baseline %zu, with queries %zu, query %zu bytes\n", (unsigned)structures[i],
           base, used, query);
    worst = query > worst ? query : worst;
    rq_scene_free(scene);
  }
  printf("stack_use: query %zu\n", worst);
  mesh_free(&m);
  return test_finish("stack_use");
}
