/* embedded_minimal.c: the smallest program on the bare-metal archive (feature bare-rt, no Rust std):
 * it routes rayq's memory through a fixed static arena, builds a one-triangle scene and traces one
 * ray. tests/c_api.rs links it with the C library alone, strips it, and fails when it grows past the
 * recorded size budget (docs/embedded.md).
 *
 * Build (from the repository root):
 *
 *   cargo rustc --profile bare --lib --crate-type staticlib --no-default-features --features bare-rt
 *   cc -std=c99 -Os -ffunction-sections -fdata-sections -Iinclude examples/embedded_minimal.c \
 *      target/bare/librayq.a -Wl,--gc-sections -s -nodefaultlibs -lc -o embedded_minimal
 *   ./embedded_minimal
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "rayq.h"

/* A bump arena: firmware often has no heap, only a block of RAM set aside. Frees are ignored, which
 * is enough for a program that builds one scene; the arena runs dry cleanly (rayq gets NULL and
 * reports RQ_STATUS_OUT_OF_MEMORY). */
static unsigned char arena[64 * 1024];
static size_t arena_used;

static void *arena_alloc(void *user, size_t size, size_t align) {
  (void)user;
  size_t at = (arena_used + align - 1) & ~(align - 1);
  if (at > sizeof arena || size > sizeof arena - at) {
    return NULL;
  }
  arena_used = at + size;
  return arena + at;
}

static void arena_free(void *user, void *ptr, size_t size, size_t align) {
  (void)user;
  (void)ptr;
  (void)size;
  (void)align;
}

int main(void) {
  rq_allocator allocator = {sizeof(rq_allocator), NULL, arena_alloc, arena_free};
  if (rq_set_allocator(&allocator) != RQ_STATUS_OK) {
    return 1;
  }
  static const float vertices[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  static const uint32_t indices[3] = {0, 1, 2};
  rq_mesh_desc mesh = {vertices, 3, 12, indices, 1};
  rq_scene *scene = NULL;
  if (rq_scene_build(&mesh, NULL, NULL, &scene) != RQ_STATUS_OK) {
    return 2;
  }
  rq_ray ray = {{0.25f, 0.25f, 1.0f}, 0.0f, {0.0f, 0.0f, -1.0f}, INFINITY};
  rq_hit hit;
  int ok = rq_scene_intersect(scene, &ray, &hit) && hit.prim == 0;
  rq_scene_free(scene);
  printf("embedded_minimal: %s, t = %g, arena used %u bytes\n", ok ? "hit" : "MISSED", (double)hit.t,
         (unsigned)arena_used);
  return ok ? 0 : 3;
}
