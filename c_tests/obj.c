/* obj.c: the OBJ helper for C programs (feature `obj`, -DRQ_WITH_OBJ): load, describe, bound, build,
 * and refuse what cannot be read, with a status of its own per reason and a message naming the file
 * and the line. Writes its OBJ files into the current directory (the runner starts
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

/* What on_error was told: how often, the last status and message. */
typedef struct captured {
  int calls;
  rq_status status;
  char message[512];
} captured;

static void capture(void *user, rq_status status, const char *message) {
  captured *c = (captured *)user;
  c->calls++;
  c->status = status;
  snprintf(c->message, sizeof c->message, "%s", message ? message : "(NULL)");
}

/* Loads `path` with rq_obj_load and with rq_obj_load_ex; both must refuse it with `want`, leave *out
 * untouched, and the callback must be told once, with a message that contains every `needles` entry. */
static void check_refused(const char *path, rq_status want, const char *const *needles, size_t n) {
  rq_obj *obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load(path, &obj), want);
  CHECK(obj == (rq_obj *)test_sentinel());

  captured c;
  memset(&c, 0, sizeof c);
  rq_obj_load_options opts;
  rq_obj_load_options_init(&opts);
  opts.on_error = capture;
  opts.user = &c;
  CHECK_STATUS(rq_obj_load_ex(path, &opts, &obj), want);
  CHECK(obj == (rq_obj *)test_sentinel());
  CHECKF(c.calls == 1, "%s: on_error called %d times", path, c.calls);
  CHECKF(c.status == want, "%s: on_error got status %u", path, (unsigned)c.status);
  for (size_t i = 0; i < n; i++) {
    CHECKF(strstr(c.message, needles[i]) != NULL, "%s: message \"%s\" lacks \"%s\"", path, c.message, needles[i]);
  }
}

static void test_refused(void) {
  /* A file that does not exist: the message names it, and there is no line to name. */
  {
    const char *needles[] = {"no-such-file.obj: cannot open: "};
    check_refused("no-such-file.obj", RQ_STATUS_OBJ_UNREADABLE, needles, 1);
  }
#if defined(__unix__)
  /* A directory opens on POSIX systems and fails at the first read. */
  {
    const char *needles[] = {".:1: cannot read: "};
    check_refused(".", RQ_STATUS_OBJ_UNREADABLE, needles, 1);
  }
#endif

  /* Malformed lines: a coordinate that is not a number, too few coordinates, a coordinate that is not
   * finite, a face of two vertices, a vertex reference that is not one. */
  CHECK(write_file("not_a_number.obj", "v 0 0 0\nv 1 x 0\n"));
  {
    const char *needles[] = {"not_a_number.obj:2: ", "\"x\" is not a number"};
    check_refused("not_a_number.obj", RQ_STATUS_OBJ_MALFORMED, needles, 2);
  }
  CHECK(write_file("short_vertex.obj", "# one comment line\nv 0 0\n"));
  {
    const char *needles[] = {"short_vertex.obj:2: ", "got 2 values"};
    check_refused("short_vertex.obj", RQ_STATUS_OBJ_MALFORMED, needles, 2);
  }
  CHECK(write_file("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"));
  {
    const char *needles[] = {"nan.obj:3: ", "not finite"};
    check_refused("nan.obj", RQ_STATUS_OBJ_MALFORMED, needles, 2);
  }
  CHECK(write_file("two_vertex_face.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n"));
  {
    const char *needles[] = {"two_vertex_face.obj:4: ", "at least 3 vertices"};
    check_refused("two_vertex_face.obj", RQ_STATUS_OBJ_MALFORMED, needles, 2);
  }
  CHECK(write_file("bad_reference.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2/x 3\n"));
  {
    const char *needles[] = {"bad_reference.obj:4: ", "\"2/x\""};
    check_refused("bad_reference.obj", RQ_STATUS_OBJ_MALFORMED, needles, 2);
  }

  /* Indices out of range: past the vertices, 0, too far back, and a vertex defined only later. */
  CHECK(write_file("bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"));
  {
    const char *needles[] = {"bad_index.obj:4: ", "index 9 is out of range", "3 vertices"};
    check_refused("bad_index.obj", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE, needles, 3);
  }
  CHECK(write_file("zero_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 0 1 2\n"));
  {
    const char *needles[] = {"zero_index.obj:5: ", "index 0"};
    check_refused("zero_index.obj", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE, needles, 2);
  }
  CHECK(write_file("far_back.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"));
  {
    const char *needles[] = {"far_back.obj:4: ", "index -4"};
    check_refused("far_back.obj", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE, needles, 2);
  }
  CHECK(write_file("forward.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n"));
  {
    const char *needles[] = {"forward.obj:3: ", "2 vertices"};
    check_refused("forward.obj", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE, needles, 2);
  }

  /* NULL arguments: refused, and the callback says which. */
  {
    captured c;
    memset(&c, 0, sizeof c);
    rq_obj_load_options opts;
    rq_obj_load_options_init(&opts);
    opts.on_error = capture;
    opts.user = &c;
    rq_obj *obj = (rq_obj *)test_sentinel();
    CHECK_STATUS(rq_obj_load_ex(NULL, &opts, &obj), RQ_STATUS_NULL_ARGUMENT);
    CHECK(obj == (rq_obj *)test_sentinel());
    CHECK(c.calls == 1 && strstr(c.message, "path") != NULL);
    CHECK_STATUS(rq_obj_load_ex("tiny.obj", &opts, NULL), RQ_STATUS_NULL_ARGUMENT);
    CHECK(c.calls == 2 && strstr(c.message, "out") != NULL);
    CHECK_STATUS(rq_obj_load(NULL, &obj), RQ_STATUS_NULL_ARGUMENT);
    CHECK_STATUS(rq_obj_load("tiny.obj", NULL), RQ_STATUS_NULL_ARGUMENT);
    CHECK(obj == (rq_obj *)test_sentinel());
  }

  /* No geometry at all: loads, has no bounds, builds an empty scene. */
  CHECK(write_file("empty.obj", "# nothing here\n"));
  rq_obj *obj = NULL;
  CHECK_STATUS(rq_obj_load("empty.obj", &obj), RQ_STATUS_OK);
  if (obj) {
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

/* rq_obj_load_options grows like rq_build_options: init fills it, and the library reads only what
 * struct_size covers. */
static void test_options(void) {
  rq_obj_load_options opts;
  memset(&opts, 0xAB, sizeof opts);
  rq_obj_load_options_init(&opts);
  CHECK(opts.struct_size == sizeof opts);
  CHECK(opts.on_error == NULL && opts.user == NULL);
  rq_obj_load_options_init(NULL);

  /* NULL options are the defaults. */
  rq_obj *obj = NULL;
  CHECK_STATUS(rq_obj_load_ex("tiny.obj", NULL, &obj), RQ_STATUS_OK);
  CHECK(obj != NULL);
  rq_obj_free(obj);

  /* A caller whose struct ends before on_error: the callback is not read, let alone called. The
   * struct sits at the very end of a guarded page, so a read past struct_size faults. */
  captured c;
  memset(&c, 0, sizeof c);
  guarded g = guarded_alloc(sizeof(uint32_t));
  uint32_t small = (uint32_t)sizeof(uint32_t);
  memcpy(g.p, &small, sizeof small);
  obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load_ex("no-such-file.obj", (const rq_obj_load_options *)(const void *)g.p, &obj),
               RQ_STATUS_OBJ_UNREADABLE);
  CHECK(obj == (rq_obj *)test_sentinel());
  guarded_free(&g);

  /* The full struct, with the callback set: told once on failure, never on success. */
  rq_obj_load_options_init(&opts);
  opts.on_error = capture;
  opts.user = &c;
  obj = NULL;
  CHECK_STATUS(rq_obj_load_ex("tiny.obj", &opts, &obj), RQ_STATUS_OK);
  CHECK(c.calls == 0);
  rq_obj_free(obj);
}

int main(void) {
  test_load();
  test_refused();
  test_options();
  return test_finish("obj");
}
