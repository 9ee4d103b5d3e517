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

/* Options whose on_error records into `c` (cleared here). */
static rq_obj_load_options capturing(captured *c) {
  memset(c, 0, sizeof *c);
  rq_obj_load_options opts;
  rq_obj_load_options_init(&opts);
  opts.on_error = capture;
  opts.user = c;
  return opts;
}

/* A file the helper must refuse: its name and text (NULL: not written, the path is used as it is),
 * the status, and what the message must contain (up to three pieces, the unused ones NULL). */
typedef struct refused_case {
  const char *path;
  const char *text;
  rq_status status;
  const char *needles[3];
} refused_case;

static const refused_case refused_cases[] = {
    /* A file that does not exist: the message names it, and there is no line to name. */
    {"no-such-file.obj", NULL, RQ_STATUS_OBJ_UNREADABLE, {"no-such-file.obj: cannot open: ", NULL, NULL}},
#if defined(__unix__)
    /* A directory opens on POSIX systems and fails at the first read. */
    {".", NULL, RQ_STATUS_OBJ_UNREADABLE, {".:1: cannot read: ", NULL, NULL}},
#endif
    /* Malformed lines: a coordinate that is not a number, too few coordinates, a coordinate that is
     * not finite, a face of two vertices, a vertex reference that is not one. */
    {"not_a_number.obj", "v 0 0 0\nv 1 x 0\n", RQ_STATUS_OBJ_MALFORMED,
     {"not_a_number.obj:2: ", "\"x\" is not a number", NULL}},
    {"short_vertex.obj", "# one comment line\nv 0 0\n", RQ_STATUS_OBJ_MALFORMED,
     {"short_vertex.obj:2: ", "got 2 values", NULL}},
    {"nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n", RQ_STATUS_OBJ_MALFORMED,
     {"nan.obj:3: ", "not finite", NULL}},
    {"two_vertex_face.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", RQ_STATUS_OBJ_MALFORMED,
     {"two_vertex_face.obj:4: ", "at least 3 vertices", NULL}},
    {"bad_reference.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2/x 3\n", RQ_STATUS_OBJ_MALFORMED,
     {"bad_reference.obj:4: ", "\"2/x\"", NULL}},
    /* Indices out of range: past the vertices, 0, too far back, and a vertex defined only later. */
    {"bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE,
     {"bad_index.obj:4: ", "index 9 is out of range", "3 vertices"}},
    {"zero_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 0 1 2\n", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE,
     {"zero_index.obj:5: ", "index 0", NULL}},
    {"far_back.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE,
     {"far_back.obj:4: ", "index -4", NULL}},
    {"forward.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE,
     {"forward.obj:3: ", "2 vertices", NULL}},
};

/* Loads the case's file with rq_obj_load and with rq_obj_load_ex; both must refuse it with its
 * status and leave *out untouched, and the callback must be told once, with a message that contains
 * every needle. */
static void check_refused(const refused_case *r) {
  if (r->text) {
    CHECK(write_file(r->path, r->text));
  }
  rq_obj *obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load(r->path, &obj), r->status);
  CHECK(obj == (rq_obj *)test_sentinel());

  captured c;
  rq_obj_load_options opts = capturing(&c);
  CHECK_STATUS(rq_obj_load_ex(r->path, &opts, &obj), r->status);
  CHECK(obj == (rq_obj *)test_sentinel());
  CHECKF(c.calls == 1, "%s: on_error called %d times", r->path, c.calls);
  CHECKF(c.status == r->status, "%s: on_error got status %u", r->path, (unsigned)c.status);
  for (size_t i = 0; i < 3 && r->needles[i]; i++) {
    CHECKF(strstr(c.message, r->needles[i]) != NULL, "%s: message \"%s\" lacks \"%s\"", r->path, c.message,
           r->needles[i]);
  }
}

static void test_refused(void) {
  for (size_t i = 0; i < sizeof refused_cases / sizeof refused_cases[0]; i++) {
    check_refused(&refused_cases[i]);
  }

  /* NULL arguments: refused, and the callback says which. */
  {
    captured c;
    rq_obj_load_options opts = capturing(&c);
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
  guarded g = guarded_alloc(sizeof(uint32_t));
  uint32_t small = (uint32_t)sizeof(uint32_t);
  memcpy(g.p, &small, sizeof small);
  obj = (rq_obj *)test_sentinel();
  CHECK_STATUS(rq_obj_load_ex("no-such-file.obj", (const rq_obj_load_options *)(const void *)g.p, &obj),
               RQ_STATUS_OBJ_UNREADABLE);
  CHECK(obj == (rq_obj *)test_sentinel());
  guarded_free(&g);

  /* The full struct, with the callback set: never told on success. */
  captured c;
  opts = capturing(&c);
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
