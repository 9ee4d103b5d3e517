/* embedded.c: the bare-metal archive (feature bare-rt, no Rust std) linked into a C program with
 * nothing but the C library. Every allocation goes through a counting arena installed with
 * rq_set_allocator: after rq_scene_free every byte has come back; an arena that runs dry at any one
 * allocation of a build gives RQ_STATUS_OUT_OF_MEMORY with nothing leaked; rq_set_allocator itself
 * refuses bad arguments and a second call; rq_set_panic_hook is accepted. */
#include "common.h"

/* ---- the counting arena ------------------------------------------------------------------------ */

/* Live blocks, so that every free can be checked against the size and alignment it was asked for. */
#define ARENA_BLOCKS 4096

typedef struct block {
  void *p;
  size_t size, align;
} block;

typedef struct arena {
  block live[ARENA_BLOCKS];
  size_t live_count;
  size_t live_bytes, peak_bytes;
  size_t allocs, frees, bad_frees;
  size_t capacity;  /* bytes the arena may hand out at once; 0 = unlimited */
  size_t fail_at;   /* refuse allocation number fail_at (1-based, counted from reset); 0 = never */
} arena;

static arena the_arena;

static void arena_reset_counts(arena *a, size_t capacity, size_t fail_at) {
  a->allocs = 0;
  a->frees = 0;
  a->peak_bytes = a->live_bytes;
  a->capacity = capacity;
  a->fail_at = fail_at;
}

static void *arena_alloc(void *user, size_t size, size_t align) {
  arena *a = (arena *)user;
  a->allocs++;
  if (a->fail_at != 0 && a->allocs == a->fail_at) {
    return NULL;
  }
  if ((a->capacity != 0 && a->live_bytes + size > a->capacity) || a->live_count == ARENA_BLOCKS) {
    return NULL;
  }
  void *p = NULL;
  if (posix_memalign(&p, align < sizeof(void *) ? sizeof(void *) : align, size) != 0) {
    return NULL;
  }
  a->live[a->live_count].p = p;
  a->live[a->live_count].size = size;
  a->live[a->live_count].align = align;
  a->live_count++;
  a->live_bytes += size;
  if (a->live_bytes > a->peak_bytes) {
    a->peak_bytes = a->live_bytes;
  }
  return p;
}

static void arena_free(void *user, void *p, size_t size, size_t align) {
  arena *a = (arena *)user;
  a->frees++;
  for (size_t i = 0; i < a->live_count; i++) {
    if (a->live[i].p == p) {
      if (a->live[i].size != size || a->live[i].align != align) {
        a->bad_frees++;
      }
      a->live_bytes -= a->live[i].size;
      a->live[i] = a->live[--a->live_count];
      free(p);
      return;
    }
  }
  a->bad_frees++; /* not ours: never free it */
}

/* ---- tests ------------------------------------------------------------------------------------- */

static void set_allocator(void) {
  rq_allocator a;
  memset(&a, 0, sizeof a);
  a.struct_size = (uint32_t)sizeof a;
  a.user = &the_arena;
  a.alloc = arena_alloc;
  a.free = arena_free;

  CHECK_STATUS(rq_set_allocator(NULL), RQ_STATUS_NULL_ARGUMENT);
  rq_allocator partial = a;
  partial.struct_size = (uint32_t)(sizeof(uint32_t));
  CHECK_STATUS(rq_set_allocator(&partial), RQ_STATUS_INVALID_ARGUMENT);
  partial = a;
  partial.free = NULL;
  CHECK_STATUS(rq_set_allocator(&partial), RQ_STATUS_NULL_ARGUMENT);
  partial = a;
  partial.alloc = NULL;
  CHECK_STATUS(rq_set_allocator(&partial), RQ_STATUS_NULL_ARGUMENT);

  /* The refusals above did not count as the one call. */
  CHECK_STATUS(rq_set_allocator(&a), RQ_STATUS_OK);
  CHECK_STATUS(rq_set_allocator(&a), RQ_STATUS_INVALID_OPERATION);
}

static void on_panic(void *user, const char *message) {
  (void)user;
  fprintf(stderr, "rayq panicked: %s\n", message);
}

/* Builds `structure` over `d` from an arena in the given state; returns the status and frees. */
static rq_status build_and_trace(const rq_mesh_desc *d, rq_structure structure, uint64_t rays, int trace_it) {
  rq_build_options o;
  rq_build_options_init(&o);
  o.structure = structure;
  o.expected_rays = rays;
  rq_scene *scene = NULL;
  rq_status s = rq_scene_build(d, &o, NULL, &scene);
  if (s != RQ_STATUS_OK) {
    CHECK(scene == NULL);
    return s;
  }
  if (trace_it) {
    /* Rays from 4 units out towards the centre of the cube [-1, 1]^3 (unit directions) meet its surface
     * between 4 - sqrt(3) and 3. */
    uint64_t rng = 99;
    size_t hits = 0;
    for (int i = 0; i < 200; i++) {
      float dir[3];
      rng_dir(&rng, dir);
      float len = sqrtf(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
      dir[0] /= len;
      dir[1] /= len;
      dir[2] /= len;
      rq_ray r = make_ray(-4.0f * dir[0], -4.0f * dir[1], -4.0f * dir[2], dir[0], dir[1], dir[2]);
      rq_hit h = trace(scene, &r);
      hits += h.prim != RQ_INVALID_ID && h.t >= 4.0f - 1.7321f - 1e-3f && h.t <= 3.0f + 1e-3f;
    }
    CHECKF(hits == 200, "structure %u: %zu of 200 rays hit", (unsigned)structure, hits);
    rq_scene_report r;
    memset(&r, 0, sizeof r);
    r.struct_size = (uint32_t)sizeof r;
    CHECK_STATUS(rq_scene_report_get(scene, &r), RQ_STATUS_OK);
    /* AUTO at this budget keeps the cube's kd-tree (since stop 25's check; the grid until then). */
    CHECK(r.structure == (structure == RQ_STRUCTURE_GRID ? RQ_STRUCTURE_GRID : RQ_STRUCTURE_KDTREE));
    CHECK(structure != RQ_STRUCTURE_AUTO || r.outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN);
    CHECKF(the_arena.live_bytes >= r.memory_bytes, "arena holds %zu bytes, the scene says %zu", the_arena.live_bytes,
           r.memory_bytes);
  }
  rq_scene_free(scene);
  return RQ_STATUS_OK;
}

static void everything_comes_back(const rq_mesh_desc *d) {
  const rq_structure structures[] = {RQ_STRUCTURE_GRID, RQ_STRUCTURE_KDTREE, RQ_STRUCTURE_AUTO};
  for (size_t i = 0; i < 3; i++) {
    arena_reset_counts(&the_arena, 0, 0);
    CHECK_STATUS(build_and_trace(d, structures[i], 1000000000000ull, 1), RQ_STATUS_OK);
    CHECKF(the_arena.allocs > 0, "structure %u: nothing went through the arena", (unsigned)structures[i]);
    CHECKF(the_arena.live_bytes == 0 && the_arena.live_count == 0,
           "structure %u: %zu bytes in %zu blocks still held after rq_scene_free", (unsigned)structures[i],
           the_arena.live_bytes, the_arena.live_count);
    CHECKF(the_arena.allocs == the_arena.frees, "structure %u: %zu allocations, %zu frees", (unsigned)structures[i],
           the_arena.allocs, the_arena.frees);
  }
  CHECK(the_arena.bad_frees == 0);

  /* A calibration handle goes through the arena too. */
  uint8_t blob[512];
  size_t len = 0;
  CHECK_STATUS(rq_calibration_to_bytes(rq_calibration_builtin(), blob, sizeof blob, &len), RQ_STATUS_OK);
  arena_reset_counts(&the_arena, 0, 0);
  rq_calibration *c = NULL;
  CHECK_STATUS(rq_calibration_from_bytes(blob, len, &c), RQ_STATUS_OK);
  CHECK(the_arena.allocs == 1 && the_arena.live_count == 1);
  rq_calibration_free(c);
  CHECK(the_arena.live_count == 0);
}

/* Refuse each allocation of a build in turn: every refusal is RQ_STATUS_OUT_OF_MEMORY (or, where the
 * build can do without the memory, success) and leaves nothing held. */
static void runs_dry(const rq_mesh_desc *d, rq_structure structure, uint64_t rays) {
  arena_reset_counts(&the_arena, 0, 0);
  CHECK_STATUS(build_and_trace(d, structure, rays, 0), RQ_STATUS_OK);
  size_t total = the_arena.allocs, peak = the_arena.peak_bytes;
  size_t out_of_memory = 0;
  for (size_t k = 1; k <= total; k++) {
    arena_reset_counts(&the_arena, 0, k);
    rq_status s = build_and_trace(d, structure, rays, 0);
    CHECKF(s == RQ_STATUS_OUT_OF_MEMORY || s == RQ_STATUS_OK, "structure %u: refusing allocation %zu of %zu gave %u",
           (unsigned)structure, k, total, (unsigned)s);
    out_of_memory += s == RQ_STATUS_OUT_OF_MEMORY;
    CHECKF(the_arena.live_bytes == 0, "structure %u: refusing allocation %zu left %zu bytes held", (unsigned)structure,
           k, the_arena.live_bytes);
  }
  CHECKF(out_of_memory * 10 >= total * 9, "structure %u: only %zu of %zu refusals failed the build", (unsigned)structure,
         out_of_memory, total);
  /* An arena with half the peak runs dry part-way through. */
  arena_reset_counts(&the_arena, peak / 2, 0);
  CHECK_STATUS(build_and_trace(d, structure, rays, 0), RQ_STATUS_OUT_OF_MEMORY);
  CHECK(the_arena.live_bytes == 0);
  arena_reset_counts(&the_arena, 0, 0);
  CHECK(the_arena.bad_frees == 0);
}

int main(void) {
  /* Before anything allocates. */
  set_allocator();
  CHECK_STATUS(rq_set_panic_hook(on_panic, NULL), RQ_STATUS_OK);
  CHECK_STATUS(rq_set_panic_hook(NULL, NULL), RQ_STATUS_OK);
  CHECK_STATUS(rq_set_panic_hook(on_panic, NULL), RQ_STATUS_OK);
  CHECK(rq_abi_version() == RQ_ABI_VERSION);

  test_mesh m = mesh_cube(8);
  rq_mesh_desc d = mesh_desc(&m);
  everything_comes_back(&d);
  runs_dry(&d, RQ_STRUCTURE_GRID, 0);
  runs_dry(&d, RQ_STRUCTURE_KDTREE, 0);
  runs_dry(&d, RQ_STRUCTURE_AUTO, 1000000000000ull);
  mesh_free(&m);
  CHECK(the_arena.live_bytes == 0);
  return test_finish("embedded");
}
