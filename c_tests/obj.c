/* obj.c: the OBJ helper for C programs (feature `obj`, -DRQ_WITH_OBJ): load, describe, bound, build,
 * and refuse what cannot be read. Writes its OBJ files into the current directory (the runner starts
 * it in a scratch directory). */
#include "common.h"

#if !defined(RQ_WITH_OBJ)
#error "compile obj.c with -DRQ_WITH_OBJ"
#endif

static int write_file(const char *path, const char *text) {
  FILE *f = fopen(path, "wb");
  if (!f) {
    fprintf(stderr, "cannot write %s\n", path);
    return 0;
  }
  int ok = fputs(text, f) >= 0;
  ok = fclose(f) == 0 && ok;
  return ok;
}

static const char *tiny_obj =
    "# two objects: a unit quad at z = 0 and a triangle at z = 1\n"
    "o quad\n"
    "v 0 0 0\n"
    "v 1 0 0\n"
    "v 1 1 0\n"
    "v 0 1 0\n"
    "vn 0 0 1\n"
    "f 1//1 2//1 3//1 4//1\n"
    "o roof\n"
    "v 0 0 1\n"
    "v 1 0 1\n"
    "v 0 1 1\n"
    "f 5 6 7\n";

static void test_load(void) {
  CHECK(write_file("tiny.obj", tiny_obj));
  rq_obj *obj = NULL;
  CHECK_STATUS(rq_obj_load("tiny.obj", &obj), RQ_STATUS_OK);
  if (!obj) {
    return;
  }
  rq_mesh_desc d;
  memset(&d, 0, sizeof d);
  CHECK_STATUS(rq_obj_mesh_desc(obj, &d), RQ_STATUS_OK);
  CHECKF(d.vertex_count == 7, "vertex_count %zu", d.vertex_count);
  CHECKF(d.triangle_count == 3, "triangle_count %zu (the quad is fanned into two)", d.triangle_count);
  CHECK(d.vertex_stride >= 12);
  CHECK(d.vertices != NULL && d.indices != NULL);
  if (d.vertices && d.indices && d.vertex_count == 7 && d.triangle_count == 3) {
    for (size_t i = 0; i < 3 * d.triangle_count; i++) {
      CHECK(d.indices[i] < d.vertex_count);
    }
    /* The second object's triangle names the second object's vertices (indices offset). */
    for (int k = 0; k < 3; k++) {
      const float *p = (const float *)(const void *)((const unsigned char *)d.vertices +
                                                     d.indices[6 + k] * d.vertex_stride);
      CHECK(p[2] == 1.0f);
    }
  }
  float lo[3], hi[3];
  CHECK_STATUS(rq_obj_bounds(obj, lo, hi), RQ_STATUS_OK);
  CHECK(lo[0] == 0.0f && lo[1] == 0.0f && lo[2] == 0.0f);
  CHECK(hi[0] == 1.0f && hi[1] == 1.0f && hi[2] == 1.0f);
  /* NULL outputs are refused, the others untouched. */
  float keep[3] = {5, 5, 5};
  CHECK_STATUS(rq_obj_bounds(obj, keep, NULL), RQ_STATUS_NULL_ARGUMENT);
  CHECK_STATUS(rq_obj_bounds(obj, NULL, keep), RQ_STATUS_NULL_ARGUMENT);
  CHECK(keep[0] == 5.0f && keep[1] == 5.0f && keep[2] == 5.0f);
  CHECK_STATUS(rq_obj_mesh_desc(obj, NULL), RQ_STATUS_NULL_ARGUMENT);

  /* Build and trace: the roof covers x + y <= 1, the quad the whole unit square. */
  rq_scene *scene = NULL;
  CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
  if (scene) {
    rq_ray r = make_ray(0.25f, 0.25f, 5.0f, 0.0f, 0.0f, -1.0f);
    rq_hit h;
    CHECK(rq_scene_intersect(scene, &r, &h));
    CHECKF(h.prim == 2 && fabsf(h.t - 4.0f) < 1e-6f, "roof: prim %u t %g", (unsigned)h.prim, (double)h.t);
    r = make_ray(0.75f, 0.75f, 5.0f, 0.0f, 0.0f, -1.0f);
    CHECK(rq_scene_intersect(scene, &r, &h));
    CHECKF(h.prim <= 1 && fabsf(h.t - 5.0f) < 1e-6f, "quad: prim %u t %g", (unsigned)h.prim, (double)h.t);
    r = make_ray(1.5f, 0.5f, 5.0f, 0.0f, 0.0f, -1.0f);
    CHECK(!rq_scene_intersect(scene, &r, &h));
    /* The scene copied what it needs: it outlives the OBJ. */
    rq_obj_free(obj);
    obj = NULL;
    r = make_ray(0.25f, 0.25f, 5.0f, 0.0f, 0.0f, -1.0f);
    CHECK(rq_scene_intersect(scene, &r, &h) && h.prim == 2);
    rq_scene_free(scene);
  }
  rq_obj_free(obj);
}

static void test_refused(void) {
  /* A file that does not exist: INVALID_ARGUMENT, *out untouched. */
  rq_obj *obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load("no-such-file.obj", &obj), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(obj == (rq_obj *)test_sentinel());
  /* A directory is not an OBJ file. */
  CHECK_STATUS(rq_obj_load(".", &obj), RQ_STATUS_INVALID_ARGUMENT);
  CHECK(obj == (rq_obj *)test_sentinel());

  /* Faces naming vertices that do not exist: refused at load, or loaded and refused at build. */
  CHECK(write_file("bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"));
  obj = (rq_obj *)test_sentinel();
  rq_status s = rq_obj_load("bad_index.obj", &obj);
  CHECKF(s == RQ_STATUS_OK || s == RQ_STATUS_INVALID_ARGUMENT, "bad index: %u (%s)", (unsigned)s, rq_status_str(s));
  if (s == RQ_STATUS_OK) {
    rq_mesh_desc d;
    CHECK_STATUS(rq_obj_mesh_desc(obj, &d), RQ_STATUS_OK);
    rq_scene *scene = (rq_scene *)test_sentinel();
    CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_INVALID_MESH);
    CHECK(scene == (rq_scene *)test_sentinel());
    rq_obj_free(obj);
  } else {
    CHECK(obj == (rq_obj *)test_sentinel());
  }

  /* A non-finite coordinate: refused at load or at build, never built. */
  CHECK(write_file("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"));
  obj = (rq_obj *)test_sentinel();
  s = rq_obj_load("nan.obj", &obj);
  CHECKF(s == RQ_STATUS_OK || s == RQ_STATUS_INVALID_ARGUMENT, "nan: %u (%s)", (unsigned)s, rq_status_str(s));
  if (s == RQ_STATUS_OK) {
    rq_mesh_desc d;
    CHECK_STATUS(rq_obj_mesh_desc(obj, &d), RQ_STATUS_OK);
    rq_scene *scene = (rq_scene *)test_sentinel();
    rq_status b = rq_scene_build(&d, NULL, NULL, &scene);
    /* tobj may read "nan" as NaN (refused by the build) or fail to parse it (refused by the load). */
    CHECKF(b == RQ_STATUS_INVALID_MESH || b == RQ_STATUS_OK, "nan build: %u (%s)", (unsigned)b, rq_status_str(b));
    if (b == RQ_STATUS_OK) {
      rq_scene_free(scene);
    }
    rq_obj_free(obj);
  }

  /* No geometry at all: loads, has no bounds, builds an empty scene. */
  CHECK(write_file("empty.obj", "# nothing here\n"));
  obj = NULL;
  s = rq_obj_load("empty.obj", &obj);
  CHECKF(s == RQ_STATUS_OK || s == RQ_STATUS_INVALID_ARGUMENT, "empty: %u (%s)", (unsigned)s, rq_status_str(s));
  if (s == RQ_STATUS_OK && obj) {
    float lo[3] = {9, 9, 9}, hi[3] = {9, 9, 9};
    CHECK_STATUS(rq_obj_bounds(obj, lo, hi), RQ_STATUS_INVALID_OPERATION);
    CHECK(lo[0] == 9.0f && hi[0] == 9.0f);
    rq_mesh_desc d;
    CHECK_STATUS(rq_obj_mesh_desc(obj, &d), RQ_STATUS_OK);
    CHECK(d.vertex_count == 0 && d.triangle_count == 0);
    rq_scene *scene = NULL;
    CHECK_STATUS(rq_scene_build(&d, NULL, NULL, &scene), RQ_STATUS_OK);
    rq_ray r = make_ray(0, 0, 5, 0, 0, -1);
    CHECK(!rq_scene_intersect(scene, &r, NULL));
    rq_scene_free(scene);
    rq_obj_free(obj);
  }
}

int main(void) {
  test_load();
  test_refused();
  return test_finish("obj");
}
