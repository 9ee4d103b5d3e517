/* plugin.c: the shared-library build used as a plugin. Two copies of librayq.so (as two plugins that
 * each embed their own Rust library would be) are loaded side by side with dlopen(RTLD_LOCAL), every
 * function is found with dlsym, and each copy builds a scene and answers a query on its own. The
 * tests/c_api.rs runner checks separately that the library exports nothing but rq_ symbols.
 * RQ_PLUGIN_A and RQ_PLUGIN_B are the two paths (compiler defines). */
#include "common.h"

#include <dlfcn.h>

typedef struct api {
  void *handle;
  void (*options_init)(rq_build_options *);
  rq_status (*build)(const rq_mesh_desc *, const rq_build_options *, const rq_calibration *, rq_scene **);
  bool (*intersect)(const rq_scene *, const rq_ray *, rq_hit *);
  void (*free_scene)(rq_scene *);
  uint32_t (*abi)(void);
  const rq_calibration *(*builtin)(void);
} api;

/* dlsym gives an object pointer; copying its bytes is the POSIX way to make it a function pointer. */
static int find(void *handle, const char *name, void *fn, size_t size) {
  void *sym = dlsym(handle, name);
  CHECKF(sym != NULL, "dlsym(%s): %s", name, dlerror());
  if (sym) {
    memcpy(fn, &sym, size);
  }
  return sym != NULL;
}

static int load(const char *path, api *a) {
  memset(a, 0, sizeof *a);
  a->handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  CHECKF(a->handle != NULL, "dlopen(%s): %s", path, dlerror());
  if (!a->handle) {
    return 0;
  }
  int ok = find(a->handle, "rq_build_options_init", &a->options_init, sizeof a->options_init);
  ok &= find(a->handle, "rq_scene_build", &a->build, sizeof a->build);
  ok &= find(a->handle, "rq_scene_intersect", &a->intersect, sizeof a->intersect);
  ok &= find(a->handle, "rq_scene_free", &a->free_scene, sizeof a->free_scene);
  ok &= find(a->handle, "rq_abi_version", &a->abi, sizeof a->abi);
  ok &= find(a->handle, "rq_calibration_builtin", &a->builtin, sizeof a->builtin);
  return ok;
}

int main(void) {
  api a, b;
  if (!load(RQ_PLUGIN_A, &a) || !load(RQ_PLUGIN_B, &b)) {
    return test_finish("plugin");
  }
  /* Two copies, two libraries: their statics are distinct. */
  CHECK(a.handle != b.handle);
  CHECK((void *)a.builtin() != (void *)b.builtin());
  CHECK(a.abi() == RQ_ABI_VERSION && b.abi() == RQ_ABI_VERSION);

  test_mesh m = mesh_cube(4);
  rq_mesh_desc d = mesh_desc(&m);
  rq_build_options o;
  a.options_init(&o);
  o.structure = RQ_STRUCTURE_KDTREE;
  rq_scene *sa = NULL, *sb = NULL;
  CHECK(a.build(&d, &o, NULL, &sa) == RQ_STATUS_OK);
  o.structure = RQ_STRUCTURE_GRID;
  CHECK(b.build(&d, &o, NULL, &sb) == RQ_STATUS_OK);
  if (sa && sb) {
    rq_ray r = make_ray(0.3f, 0.1f, 5.0f, 0.0f, 0.0f, -1.0f);
    rq_hit ha, hb;
    CHECK(a.intersect(sa, &r, &ha));
    CHECK(b.intersect(sb, &r, &hb));
    CHECKF(same_hit(&ha, &hb) && ha.t == 4.0f, "t %g and %g", (double)ha.t, (double)hb.t);
  }
  a.free_scene(sa);
  b.free_scene(sb);
  mesh_free(&m);
  CHECK(dlclose(a.handle) == 0);
  CHECK(dlclose(b.handle) == 0);
  return test_finish("plugin");
}
