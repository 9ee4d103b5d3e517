/* calibration.c: the calibration blob through the C ABI: the built-in calibration, writing and reading
 * a blob, refusing every truncation and every single corrupted bit with a calibration status and
 * *out untouched, and building scenes with a loaded calibration. */
#include "common.h"

#define BUF 4096

static int is_calib_status(rq_status s) {
  return s == RQ_STATUS_CALIB_BAD_MAGIC || s == RQ_STATUS_CALIB_UNSUPPORTED_VERSION ||
         s == RQ_STATUS_CALIB_TRUNCATED || s == RQ_STATUS_CALIB_CHECKSUM || s == RQ_STATUS_CALIB_VALUE_OUT_OF_RANGE;
}

/* The committed default blob, read from its file: it loads, equals the built-in calibration, and
 * AUTO scenes built with it report a decision whose outcome matches the structure they hold. */
static void test_blob_file(const char *path, const unsigned char *builtin_blob, size_t builtin_len) {
  FILE *f = fopen(path, "rb");
  CHECKF(f != NULL, "cannot open %s", path);
  if (!f) {
    return;
  }
  unsigned char data[BUF];
  size_t n = fread(data, 1, sizeof data, f);
  fclose(f);
  rq_calibration *calib = NULL;
  CHECK_STATUS(rq_calibration_from_bytes(data, n, &calib), RQ_STATUS_OK);
  CHECKF(n == builtin_len && memcmp(data, builtin_blob, n) == 0, "%s differs from the built-in blob", path);
  if (!calib) {
    return;
  }
  test_mesh m = mesh_cube(6);
  rq_mesh_desc d = mesh_desc(&m);
  const uint64_t budgets[] = {1, 1000000000000ull, 0};
  for (size_t i = 0; i < sizeof budgets / sizeof budgets[0]; i++) {
    rq_build_options o;
    rq_build_options_init(&o);
    o.expected_rays = budgets[i];
    rq_scene *scene = NULL;
    CHECK_STATUS(rq_scene_build(&d, &o, calib, &scene), RQ_STATUS_OK);
    if (!scene) {
      continue;
    }
    rq_scene_report r;
    memset(&r, 0, sizeof r);
    r.struct_size = (uint32_t)sizeof r;
    CHECK_STATUS(rq_scene_report_get(scene, &r), RQ_STATUS_OK);
    CHECKF(r.grid_ray_seconds > 0 && r.kd_ray_seconds > 0 && r.kd_build_seconds > 0,
           "budget %llu: estimates %g %g %g", (unsigned long long)budgets[i], r.grid_ray_seconds,
           r.kd_ray_seconds, r.kd_build_seconds);
    if (budgets[i] == 0) {
      CHECK(r.outcome == RQ_OUTCOME_ONLINE_ON_GRID && r.structure == RQ_STRUCTURE_GRID);
    } else if (r.outcome == RQ_OUTCOME_ABOVE_BREAK_EVEN) {
      /* At W*, or as a trial: the build at most 1/16 of the grid's estimated trace time (README,
         "How well it chooses"). */
      CHECK(r.structure == RQ_STRUCTURE_KDTREE &&
            ((double)budgets[i] >= r.break_even_rays ||
             (double)budgets[i] * r.grid_ray_seconds >= 16.0 * r.kd_build_seconds));
    } else {
      CHECKF(r.structure == RQ_STRUCTURE_GRID &&
                 (r.outcome == RQ_OUTCOME_GRID_FASTER_PER_RAY || (double)budgets[i] < r.break_even_rays),
             "budget %llu: outcome %u with W* %g", (unsigned long long)budgets[i], (unsigned)r.outcome,
             r.break_even_rays);
    }
    rq_scene_free(scene);
  }
  mesh_free(&m);
  rq_calibration_free(calib);
}

int main(void) {
  const rq_calibration *builtin = rq_calibration_builtin();
  CHECK(builtin != NULL);
  if (!builtin) {
    return test_finish("calibration");
  }

  /* Write the built-in calibration. */
  unsigned char blob[BUF];
  size_t len = 0;
  CHECK_STATUS(rq_calibration_to_bytes(builtin, blob, sizeof blob, &len), RQ_STATUS_OK);
  CHECKF(len > 12 && len < BUF, "blob length %zu", len);
  if (!(len > 12 && len < BUF)) {
    return test_finish("calibration");
  }

  /* A buffer one byte short: refused, nothing written. */
  {
    unsigned char small[BUF];
    memset(small, 0xEE, sizeof small);
    size_t written = 4242;
    CHECK_STATUS(rq_calibration_to_bytes(builtin, small, len - 1, &written), RQ_STATUS_INVALID_ARGUMENT);
    CHECK(written == 4242);
    size_t untouched = 0;
    for (size_t i = 0; i < sizeof small; i++) {
      untouched += small[i] == 0xEE;
    }
    CHECKF(untouched == sizeof small, "%zu bytes of a too-small buffer were written", sizeof small - untouched);
    CHECK_STATUS(rq_calibration_to_bytes(builtin, small, 0, &written), RQ_STATUS_INVALID_ARGUMENT);
    CHECK(written == 4242);
    /* Size query: NULL buffer with zero capacity reports the length; NULL with a capacity is refused. */
    size_t needed = 0;
    CHECK_STATUS(rq_calibration_to_bytes(builtin, NULL, 0, &needed), RQ_STATUS_OK);
    CHECK(needed == len);
    CHECK_STATUS(rq_calibration_to_bytes(builtin, NULL, 16, &written), RQ_STATUS_NULL_ARGUMENT);
    CHECK(written == 4242);
    /* A buffer of exactly the blob's length, ending at an inaccessible page; and one byte short. */
    guarded exact = guarded_alloc(len);
    CHECK_STATUS(rq_calibration_to_bytes(builtin, exact.p, len, &written), RQ_STATUS_OK);
    CHECK(written == len && memcmp(exact.p, blob, len) == 0);
    guarded_free(&exact);
    guarded short_buf = guarded_alloc(len - 1);
    written = 4242;
    CHECK_STATUS(rq_calibration_to_bytes(builtin, short_buf.p, len - 1, &written), RQ_STATUS_INVALID_ARGUMENT);
    CHECK(written == 4242);
    guarded_free(&short_buf);
  }

  /* Read it back: a new handle, which writes the same bytes. */
  rq_calibration *loaded = NULL;
  CHECK_STATUS(rq_calibration_from_bytes(blob, len, &loaded), RQ_STATUS_OK);
  CHECK(loaded != NULL && loaded != (const rq_calibration *)builtin);
  if (loaded) {
    unsigned char again[BUF];
    size_t len2 = 0;
    CHECK_STATUS(rq_calibration_to_bytes(loaded, again, sizeof again, &len2), RQ_STATUS_OK);
    CHECK(len2 == len && memcmp(again, blob, len) == 0);

    /* Scenes built with it behave like scenes built with the built-in one. */
    test_mesh m = mesh_cube(4);
    rq_mesh_desc d = mesh_desc(&m);
    rq_scene *a = NULL, *b = NULL;
    CHECK_STATUS(rq_scene_build(&d, NULL, loaded, &a), RQ_STATUS_OK);
    CHECK_STATUS(rq_scene_build(&d, NULL, builtin, &b), RQ_STATUS_OK);
    /* The scene does not depend on the calibration handle staying alive. */
    rq_calibration_free(loaded);
    loaded = NULL;
    if (a && b) {
      uint64_t rng = 3;
      for (int i = 0; i < 500; i++) {
        rq_ray r = make_ray(rng_float(&rng, -3, 3), rng_float(&rng, -3, 3), rng_float(&rng, -3, 3), 0, 0, 0);
        rng_dir(&rng, r.dir);
        rq_hit ha, hb;
        rq_scene_intersect(a, &r, &ha);
        rq_scene_intersect(b, &r, &hb);
        CHECK(same_hit(&ha, &hb));
      }
    }
    rq_scene_free(a);
    rq_scene_free(b);
    mesh_free(&m);
  }

  /* Every truncation is refused, from a block of exactly that length that ends at an inaccessible
   * page (reading past the length faults). */
  for (size_t n = 0; n < len; n++) {
    guarded block = guarded_alloc(n);
    unsigned char *cut = block.p;
    memcpy(cut, blob, n);
    rq_calibration *out = (rq_calibration *)test_sentinel();
    rq_status s = rq_calibration_from_bytes(cut, n, &out);
    CHECKF(is_calib_status(s), "blob cut to %zu bytes: %u (%s)", n, (unsigned)s, rq_status_str(s));
    CHECKF(out == (rq_calibration *)test_sentinel(), "blob cut to %zu bytes: *out written", n);
    if (s == RQ_STATUS_OK && out != (rq_calibration *)test_sentinel()) {
      rq_calibration_free(out);
    }
    guarded_free(&block);
  }
  /* A blob cut by one byte is a length problem, not anything else. */
  {
    rq_calibration *out = (rq_calibration *)test_sentinel();
    CHECK_STATUS(rq_calibration_from_bytes(blob, len - 1, &out), RQ_STATUS_CALIB_TRUNCATED);
    /* One byte too many. */
    unsigned char longer[BUF];
    memcpy(longer, blob, len);
    longer[len] = 0;
    CHECK_STATUS(rq_calibration_from_bytes(longer, len + 1, &out), RQ_STATUS_CALIB_TRUNCATED);
    CHECK(out == (rq_calibration *)test_sentinel());
  }

  /* Every single flipped bit is refused with a calibration status; a bad first byte is bad magic. */
  int accepted = 0;
  for (size_t i = 0; i < len; i++) {
    for (int bit = 0; bit < 8; bit++) {
      unsigned char bad[BUF];
      memcpy(bad, blob, len);
      bad[i] ^= (unsigned char)(1u << bit);
      rq_calibration *out = (rq_calibration *)test_sentinel();
      rq_status s = rq_calibration_from_bytes(bad, len, &out);
      if (s == RQ_STATUS_OK) {
        accepted++;
        if (out != (rq_calibration *)test_sentinel()) {
          rq_calibration_free(out);
        }
      }
      CHECKF(is_calib_status(s), "bit %d of byte %zu flipped: %u (%s)", bit, i, (unsigned)s, rq_status_str(s));
      CHECKF(out == (rq_calibration *)test_sentinel() || s == RQ_STATUS_OK, "bit %d of byte %zu: *out written",
             bit, i);
      if (i == 0) {
        CHECK(s == RQ_STATUS_CALIB_BAD_MAGIC);
      }
    }
  }
  CHECKF(accepted == 0, "%d corrupted blobs accepted", accepted);

  /* Garbage of the right length. */
  {
    unsigned char junk[BUF];
    uint64_t rng = 17;
    for (size_t i = 0; i < len; i++) {
      junk[i] = (unsigned char)rng_next(&rng);
    }
    rq_calibration *out = (rq_calibration *)test_sentinel();
    rq_status s = rq_calibration_from_bytes(junk, len, &out);
    CHECK(is_calib_status(s));
    CHECK(out == (rq_calibration *)test_sentinel());
  }

  /* Freeing the built-in calibration (or NULL) is a no-op. */
  rq_calibration_free((rq_calibration *)builtin);
  rq_calibration_free(NULL);
  CHECK(rq_calibration_builtin() == builtin);
  {
    size_t len3 = 0;
    unsigned char third[BUF];
    CHECK_STATUS(rq_calibration_to_bytes(rq_calibration_builtin(), third, sizeof third, &len3), RQ_STATUS_OK);
    CHECK(len3 == len && memcmp(third, blob, len) == 0);
  }
  test_blob_file(RQ_DEFAULT_BLOB, blob, len);
  return test_finish("calibration");
}
