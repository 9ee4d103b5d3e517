//! The C conformance suite. Builds the static library once (a nested `cargo rustc` into its own target
//! directory), compiles every program in `c_tests/` and the C examples with the platform's C compiler
//! (found by the `cc` crate) as strict C99 with every warning an error and, where the compiler has
//! them, AddressSanitizer and UndefinedBehaviorSanitizer, links them with the library and runs them.
//! A C program reports failures on stderr and exits non-zero; this file turns that into a failed test
//! that shows the program's output.
//!
//! `RAYQ_C_NO_SANITIZERS=1` turns the sanitizers off (for compilers or machines where they misbehave).

use std::collections::BTreeSet;
use std::ffi::OsStr;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::thread;
use std::time::{Duration, Instant};

/// The target triple this test was built for (from build.rs); the C compiler and the library use it.
const TARGET: &str = env!("RAYQ_BUILD_TARGET");

/// Strict C99, every warning an error.
const STRICT_C99: &[&str] = &["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror"];

/// The sanitizers, when the compiler and the machine support them.
const SANITIZERS: &[&str] = &["-fsanitize=address,undefined", "-fno-sanitize-recover=all"];

/// Longest a compiled C program may run before it is killed and the test fails.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// The programs in `c_tests/` that are linked and run, each by its own `#[test]` below.
const RUN_TESTS: &[&str] = &[
    "budget",
    "calibration",
    "clock",
    "embedded",
    "geometries",
    "hostile_mesh",
    "kd_quality",
    "lifecycle",
    "memory_monitor",
    "obj",
    "plugin",
    "precision",
    "queries",
    "report",
    "stack_use",
    "threads",
];

/// The programs in `c_tests/` that are only compiled (by `header_*` below).
const COMPILE_ONLY: &[&str] = &["header_only"];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh scratch directory for one test under `target/tmp/c_api/`.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("c_api")
        .join(name);
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
    dir
}

fn exe_name(name: &str) -> String {
    format!("{name}{}", std::env::consts::EXE_SUFFIX)
}

/// The static library, built once per test process and shared by every test.
fn library() -> &'static Path {
    static LIB: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    match LIB.get_or_init(build_library) {
        Ok(path) => path,
        Err(e) => panic!("{e}"),
    }
}

fn build_library() -> Result<PathBuf, String> {
    build_crate(
        "c-api",
        &["--crate-type", "staticlib", "--features", "capi,obj"],
        "debug",
        if TARGET.contains("msvc") {
            "rayq.lib"
        } else {
            "librayq.a"
        },
    )
}

/// Runs `cargo rustc --lib <args> --target TARGET` into `<target dir>/<dir>` and returns the path of
/// `<profile>/<file>` there. Each kind of library has a target directory of its own: the outer
/// `cargo test` may still hold the lock on the main one, and one directory per crate type keeps each
/// build's fingerprint from invalidating the others'. CARGO_TARGET_TMPDIR is `<target dir>/tmp`, so
/// this honours a custom CARGO_TARGET_DIR.
fn build_crate(dir: &str, args: &[&str], profile: &str, file: &str) -> Result<PathBuf, String> {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let target_dir = tmp.parent().unwrap_or(tmp).join(dir);
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(root())
        .args(["rustc", "--lib"])
        .args(args)
        .args(["--target", TARGET])
        .arg("--target-dir")
        .arg(&target_dir);
    let started = Instant::now();
    let out = cmd
        .output()
        .map_err(|e| format!("cannot run {cmd:?}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "building the library failed ({}):\n{cmd:?}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let lib = target_dir.join(TARGET).join(profile).join(file);
    if !lib.is_file() {
        return Err(format!(
            "cargo succeeded but {} does not exist",
            lib.display()
        ));
    }
    eprintln!(
        "c_api: library ready in {:.1} s: {}",
        started.elapsed().as_secs_f64(),
        lib.display()
    );
    Ok(lib)
}

/// The system libraries a Rust static library needs (`rustc --print native-static-libs`).
fn native_libs() -> &'static [&'static str] {
    if TARGET.contains("linux") {
        &[
            "-lgcc_s",
            "-lutil",
            "-lrt",
            "-lpthread",
            "-lm",
            "-ldl",
            "-lc",
        ]
    } else if TARGET.contains("apple") {
        &["-lSystem", "-lc", "-lm"]
    } else {
        &["-lm", "-lpthread", "-ldl", "-lgcc_s"]
    }
}

/// The C (or C++) compiler the `cc` crate picks for this target, honouring CC/CXX and CFLAGS.
fn compiler(cpp: bool) -> Command {
    cc::Build::new()
        .target(TARGET)
        .host(TARGET)
        .opt_level(1)
        .cargo_metadata(false)
        .cpp(cpp)
        .get_compiler()
        .to_command()
}

/// The sanitizer flags if a trivial program compiles, links and runs with them, else none.
fn sanitizer_flags() -> &'static [&'static str] {
    static SUPPORTED: OnceLock<bool> = OnceLock::new();
    let supported = *SUPPORTED.get_or_init(|| {
        if std::env::var_os("RAYQ_C_NO_SANITIZERS").is_some_and(|v| v != "0") {
            eprintln!("c_api: sanitizers turned off by RAYQ_C_NO_SANITIZERS");
            return false;
        }
        let dir = scratch("sanitizer-probe");
        let src = dir.join("probe.c");
        fs::write(&src, "#include <stdlib.h>\nint main(void) { void *p = malloc(8); free(p); return 0; }\n")
            .expect("write probe.c");
        let exe = dir.join(exe_name("probe"));
        let mut cc = compiler(false);
        cc.args(SANITIZERS).arg(&src).arg("-o").arg(&exe);
        let ok = run_with_timeout(&mut cc, &dir, "compile").is_ok_and(|r| r.success)
            && run_with_timeout(sanitizer_env(&mut Command::new(&exe)), &dir, "probe").is_ok_and(|r| r.success);
        if !ok {
            eprintln!("c_api: this compiler or machine cannot run -fsanitize=address,undefined; testing without");
        }
        ok
    });
    if supported {
        SANITIZERS
    } else {
        &[]
    }
}

fn sanitizer_env(cmd: &mut Command) -> &mut Command {
    if std::env::var_os("ASAN_OPTIONS").is_none() {
        cmd.env(
            "ASAN_OPTIONS",
            "detect_leaks=1:strict_string_checks=1:check_initialization_order=1",
        );
    }
    if std::env::var_os("UBSAN_OPTIONS").is_none() {
        cmd.env("UBSAN_OPTIONS", "print_stacktrace=1:halt_on_error=1");
    }
    cmd
}

/// What a finished process said.
struct Ran {
    success: bool,
    status: String,
    stdout: String,
    stderr: String,
}

impl Ran {
    fn describe(&self, what: &str) -> String {
        format!(
            "{what}: {}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.status, self.stdout, self.stderr
        )
    }
}

/// Runs `cmd` in `dir` with its output captured in files (no pipe can fill up), killing it after
/// [`RUN_TIMEOUT`].
fn run_with_timeout(cmd: &mut Command, dir: &Path, label: &str) -> Result<Ran, String> {
    let out_path = dir.join(format!("{label}.stdout"));
    let err_path = dir.join(format!("{label}.stderr"));
    let out = fs::File::create(&out_path).map_err(|e| e.to_string())?;
    let err = fs::File::create(&err_path).map_err(|e| e.to_string())?;
    let mut child = cmd
        .current_dir(dir)
        .stdin(std::process::Stdio::null())
        .stdout(out)
        .stderr(err)
        .spawn()
        .map_err(|e| format!("cannot start {cmd:?}: {e}"))?;
    let started = Instant::now();
    let status = loop {
        match child.try_wait().map_err(|e| e.to_string())? {
            Some(status) => break Some(status),
            None if started.elapsed() > RUN_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            None => thread::sleep(Duration::from_millis(10)),
        }
    };
    let read = |p: &Path| String::from_utf8_lossy(&fs::read(p).unwrap_or_default()).into_owned();
    Ok(Ran {
        success: status.is_some_and(|s| s.success()),
        status: match status {
            Some(s) => s.to_string(),
            None => format!("killed after {} s", RUN_TIMEOUT.as_secs()),
        },
        stdout: read(&out_path),
        stderr: read(&err_path),
    })
}

/// Compiles and links `source` (strict C99, sanitizers when available) into `dir`, or panics with the
/// compiler's output.
fn build_program(dir: &Path, name: &str, source: &Path, defines: &[&str]) -> PathBuf {
    let mut link: Vec<&OsStr> = vec![library().as_os_str()];
    link.extend(native_libs().iter().map(OsStr::new));
    build_program_with(
        dir,
        name,
        source,
        &[&["-g"], sanitizer_flags(), defines].concat(),
        &link,
    )
}

/// Compiles `source` as strict C99 with `flags` and links it with `link` (libraries, linker flags),
/// or panics with the compiler's output.
fn build_program_with(
    dir: &Path,
    name: &str,
    source: &Path,
    flags: &[&str],
    link: &[&OsStr],
) -> PathBuf {
    let exe = dir.join(exe_name(name));
    let mut cmd = compiler(false);
    cmd.args(STRICT_C99)
        .args(flags)
        .arg("-I")
        .arg(root().join("include"))
        .arg("-I")
        .arg(root().join("c_tests"))
        .arg(source)
        .arg("-o")
        .arg(&exe)
        .args(link);
    let ran = run_with_timeout(&mut cmd, dir, "compile").unwrap_or_else(|e| panic!("{e}"));
    assert!(
        ran.success,
        "{}\n{cmd:?}",
        ran.describe(&format!("compiling {}", source.display()))
    );
    exe
}

/// Runs a compiled program with `args` in `dir`.
fn run_program(exe: &Path, dir: &Path, args: &[&str]) -> Ran {
    let mut cmd = Command::new(exe);
    cmd.args(args);
    run_with_timeout(sanitizer_env(&mut cmd), dir, "run").unwrap_or_else(|e| panic!("{e}"))
}

/// Compiles `c_tests/<name>.c`, runs it, and fails with its output unless it exits 0 and reports
/// zero failures.
fn run_c_test(name: &str) {
    run_c_test_with(name, &[]);
}

/// Compiles and runs `c_tests/{name}.c` with extra compiler flags.
fn run_c_test_with(name: &str, flags: &[&str]) {
    let dir = scratch(name);
    let source = root().join("c_tests").join(format!("{name}.c"));
    let mut all = vec!["-DRQ_WITH_OBJ"];
    all.extend_from_slice(flags);
    let exe = build_program(&dir, name, &source, &all);
    check_c_test_run(name, &run_program(&exe, &dir, &[]));
}

/// Fails unless a C test exited 0 and printed its summary line with zero failures.
fn check_c_test_run(name: &str, ran: &Ran) {
    assert!(
        ran.success,
        "{}",
        ran.describe(&format!("c_tests/{name}.c failed"))
    );
    let summary = format!("{name}: ");
    assert!(
        ran.stdout
            .lines()
            .any(|l| l.starts_with(&summary) && l.ends_with(" 0 failures")),
        "{}",
        ran.describe(&format!(
            "c_tests/{name}.c exited 0 without its summary line"
        ))
    );
    eprint!("{}", ran.stdout);
}

#[test]
fn c_calibration() {
    let blob = root().join("calib").join("default.rqcal");
    let define = format!("-DRQ_DEFAULT_BLOB=\"{}\"", blob.display());
    run_c_test_with("calibration", &[&define]);
}

#[test]
fn c_geometries() {
    run_c_test("geometries");
}

#[test]
fn c_hostile_mesh() {
    run_c_test("hostile_mesh");
}

#[test]
fn c_budget() {
    run_c_test("budget");
}

#[test]
fn c_kd_quality() {
    run_c_test("kd_quality");
}

#[test]
fn c_lifecycle() {
    run_c_test("lifecycle");
}

#[test]
fn c_clock() {
    run_c_test("clock");
}

#[test]
fn c_memory_monitor() {
    run_c_test("memory_monitor");
}

#[test]
fn c_obj() {
    run_c_test("obj");
}

#[test]
fn c_precision() {
    run_c_test("precision");
}

#[test]
fn c_queries() {
    run_c_test("queries");
}

#[test]
fn c_report() {
    run_c_test("report");
}

#[test]
fn c_threads() {
    run_c_test("threads");
}

/// Every `.c` file in `c_tests/` is run or compiled by a test here, so none is forgotten.
#[test]
fn every_c_test_has_a_runner() {
    let on_disk: BTreeSet<String> = fs::read_dir(root().join("c_tests"))
        .expect("read c_tests/")
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            e.file_name()
                .to_str()
                .and_then(|n| n.strip_suffix(".c"))
                .map(str::to_owned)
        })
        .collect();
    let known: BTreeSet<String> = RUN_TESTS
        .iter()
        .chain(COMPILE_ONLY)
        .map(|s| s.to_string())
        .collect();
    assert_eq!(
        on_disk, known,
        "c_tests/ and the lists in tests/c_api.rs disagree"
    );
}

/// Compiles `c_tests/header_only.c` (the header and nothing else) to an object file.
fn compile_header_only(dir: &Path, cpp: bool, flags: &[&str], label: &str) {
    let mut cmd = compiler(cpp);
    if cpp {
        cmd.args(["-x", "c++"]);
    }
    cmd.args(flags)
        .arg("-I")
        .arg(root().join("include"))
        .arg("-c")
        .arg(root().join("c_tests/header_only.c"))
        .arg("-o")
        .arg(dir.join(format!("{label}.o")));
    let ran = run_with_timeout(&mut cmd, dir, label).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        ran.success,
        "{}\n{cmd:?}",
        ran.describe(&format!("include/rayq.h does not compile ({label})"))
    );
}

#[test]
fn header_compiles_as_strict_c() {
    let dir = scratch("header_c");
    compile_header_only(&dir, false, STRICT_C99, "c99");
    compile_header_only(
        &dir,
        false,
        &[STRICT_C99, &["-DRQ_WITH_OBJ"]].concat(),
        "c99_obj",
    );
    compile_header_only(
        &dir,
        false,
        &[
            "-std=c11",
            "-Wall",
            "-Wextra",
            "-Wpedantic",
            "-Werror",
            "-DRQ_WITH_OBJ",
        ],
        "c11",
    );
}

#[test]
fn header_compiles_as_cpp() {
    let dir = scratch("header_cpp");
    let strict = ["-std=c++11", "-Wall", "-Wextra", "-Wpedantic", "-Werror"];
    compile_header_only(&dir, true, &strict, "cpp11");
    compile_header_only(
        &dir,
        true,
        &[&strict[..], &["-DRQ_WITH_OBJ"]].concat(),
        "cpp11_obj",
    );
}

#[test]
fn example_minimal() {
    let dir = scratch("example_minimal");
    let exe = build_program(&dir, "minimal", &root().join("examples/minimal.c"), &[]);
    let ran = run_program(&exe, &dir, &[]);
    assert!(ran.success, "{}", ran.describe("examples/minimal.c failed"));
    assert!(
        ran.stdout.contains("hit triangle 0") && ran.stdout.contains("missed"),
        "{}",
        ran.describe("examples/minimal.c did not print the hit and the miss")
    );
}

/// examples/buildtime.c compiles strictly, times as many builds as asked and names the structure
/// each made, and refuses bad arguments and a file it cannot read.
#[test]
fn example_buildtime() {
    let teapot = root().join("scenes/teapot.obj");
    let teapot = teapot.to_str().expect("UTF-8 path");
    let dir = scratch("example_buildtime");
    let exe = build_program(
        &dir,
        "buildtime",
        &root().join("examples/buildtime.c"),
        &["-DRQ_WITH_OBJ"],
    );
    for (structure, builds, made) in [("grid", 3, "grid"), ("kdtree", 2, "kd-tree")] {
        let ran = run_program(&exe, &dir, &[teapot, &builds.to_string(), structure]);
        assert!(
            ran.success,
            "{}",
            ran.describe("examples/buildtime.c failed")
        );
        let lines: Vec<&str> = ran.stdout.lines().collect();
        assert_eq!(lines.len(), builds, "{}", ran.describe("one line a build"));
        for (i, line) in lines.iter().enumerate() {
            assert!(
                line.starts_with(&format!("build {i} ({made}): "))
                    && line.contains(" Mtri/s, ")
                    && line.ends_with(" page faults"),
                "{}",
                ran.describe("a build's line")
            );
        }
    }
    let missing = dir.join("missing.obj");
    let missing = missing.to_str().expect("UTF-8 path");
    let refused: [&[&str]; 5] = [
        &[missing],
        &[teapot, "0"],
        &[teapot, "kdtree"],
        &[teapot, "2", "kd-tree"],
        &[teapot, "2", "grid", "extra"],
    ];
    for args in refused {
        let ran = run_program(&exe, &dir, args);
        assert!(
            !ran.success && ran.stdout.is_empty(),
            "{}",
            ran.describe(&format!("{args:?} must be refused before any build"))
        );
    }
}

/// Reads a binary PPM: (width, height, pixels).
fn read_ppm(path: &Path) -> (usize, usize, Vec<u8>) {
    let bytes = fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // The header is "P6\n<w> <h>\n255\n" (render.c writes exactly this form).
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        assert!(
            at > start && at < bytes.len(),
            "{}: truncated PPM header",
            path.display()
        );
        fields.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
    }
    at += 1; // the single whitespace byte after maxval
    assert_eq!(fields[0], "P6", "{}: not a binary PPM", path.display());
    assert_eq!(fields[3], "255", "{}: maxval", path.display());
    let w: usize = fields[1].parse().expect("width");
    let h: usize = fields[2].parse().expect("height");
    (w, h, bytes[at..].to_vec())
}

#[test]
fn example_render() {
    let teapot = root().join("scenes/teapot.obj");
    assert!(
        teapot.is_file(),
        "{} is missing (copy it from the shared scene set)",
        teapot.display()
    );
    let teapot = teapot.to_str().expect("UTF-8 path");
    let dir = scratch("example_render");
    let exe = build_program(
        &dir,
        "render",
        &root().join("examples/render.c"),
        &["-DRQ_WITH_OBJ"],
    );

    let render = |out: &str, extra: &[&str]| -> Ran {
        let mut args = vec![teapot, out];
        args.extend_from_slice(extra);
        run_program(&exe, &dir, &args)
    };

    // Non-square, so a swapped width and height shows.
    let ran = render("auto.ppm", &["64", "48"]);
    assert!(ran.success, "{}", ran.describe("examples/render.c failed"));
    for needle in ["rays/s", "structure", "memory"] {
        assert!(
            ran.stdout.contains(needle),
            "{}",
            ran.describe(&format!("render did not print {needle:?}"))
        );
    }
    let (w, h, pixels) = read_ppm(&dir.join("auto.ppm"));
    assert_eq!((w, h), (64, 48));
    assert_eq!(pixels.len(), w * h * 3, "pixel data size");
    // The teapot is in the middle of the picture, the background in the corners.
    let px = |x: usize, y: usize| &pixels[3 * (y * w + x)..3 * (y * w + x) + 3];
    assert_ne!(
        px(w / 2, h / 2),
        px(0, 0),
        "the centre pixel is background: the teapot is not in view"
    );
    let distinct: BTreeSet<&[u8]> = pixels.chunks(3).collect();
    assert!(
        distinct.len() >= 16,
        "only {} distinct colours: no shading",
        distinct.len()
    );

    // The grid forced, and the default size.
    let ran = render("grid.ppm", &["64", "48", "grid"]);
    assert!(ran.success, "{}", ran.describe("render with grid failed"));
    let grid = fs::read(dir.join("grid.ppm")).expect("grid.ppm");
    assert_eq!(
        grid,
        fs::read(dir.join("auto.ppm")).expect("auto.ppm"),
        "auto and grid images differ"
    );

    // The kd-tree: identical hits give an identical image.
    let ran = render("kdtree.ppm", &["64", "48", "kdtree"]);
    assert!(ran.success, "{}", ran.describe("render with kdtree failed"));
    assert_eq!(
        fs::read(dir.join("kdtree.ppm")).expect("kdtree.ppm"),
        grid,
        "kd-tree and grid images differ"
    );

    // Bad command lines: a usage message and a non-zero exit.
    let bad: [&[&str]; 5] = [
        &[teapot],
        &[teapot, "x.ppm", "64"],
        &[teapot, "x.ppm", "0", "48"],
        &[teapot, "x.ppm", "64", "48x"],
        &[teapot, "x.ppm", "64", "48", "octree"],
    ];
    for args in bad {
        let ran = run_program(&exe, &dir, args);
        assert!(
            !ran.success,
            "{}",
            ran.describe(&format!("render accepted {args:?}"))
        );
        assert!(
            ran.stderr.contains("usage"),
            "{}",
            ran.describe(&format!("no usage message for {args:?}"))
        );
    }
    let ran = run_program(&exe, &dir, &["no-such-scene.obj", "x.ppm"]);
    assert!(
        !ran.success,
        "{}",
        ran.describe("render accepted a missing scene")
    );
    // The OBJ helper's message reaches the user: the file, the line, the status's name.
    for (name, text, needles) in [
        (
            "no-such-scene.obj",
            None,
            &["no-such-scene.obj: cannot open", "RQ_STATUS_OBJ_UNREADABLE"][..],
        ),
        (
            "broken.obj",
            Some("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"),
            &[
                "broken.obj:4: face vertex index 7",
                "RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE",
            ][..],
        ),
    ] {
        if let Some(text) = text {
            fs::write(dir.join(name), text).expect("write the broken scene");
        }
        let ran = run_program(&exe, &dir, &[name, "x.ppm"]);
        for needle in needles {
            assert!(
                !ran.success && ran.stderr.contains(needle),
                "{}",
                ran.describe(&format!("render {name}: no {needle:?} on stderr"))
            );
        }
    }
}

// ---- embedded and plugin builds (docs/embedded.md) ---------------------------------------------

/// The bare-metal archive: no std, libm math, panics abort through the C hook, the allocator hooks.
/// Built once per test process with the documented command.
fn bare_library() -> &'static Path {
    static LIB: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let built = LIB.get_or_init(|| {
        build_crate(
            "c-api-bare",
            &[
                "--profile",
                "bare",
                "--crate-type",
                "staticlib",
                "--no-default-features",
                "--features",
                "bare-rt",
            ],
            "bare",
            "librayq.a",
        )
    });
    match built {
        Ok(path) => path,
        Err(e) => panic!("{e}"),
    }
}

/// The plugin: the shared library with the C ABI (debug profile; the symbol policy is the same).
fn plugin_library() -> &'static Path {
    static LIB: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let built = LIB.get_or_init(|| {
        build_crate(
            "c-api-plugin",
            &["--crate-type", "cdylib", "--features", "capi"],
            "debug",
            "librayq.so",
        )
    });
    match built {
        Ok(path) => path,
        Err(e) => panic!("{e}"),
    }
}

/// One symbol as `nm -P` prints it: the archive member (empty for a plain file), name, type letter.
struct Symbol {
    member: String,
    name: String,
    kind: char,
}

/// `nm -P` with `args` on `file`, one [`Symbol`] per line.
fn nm_symbols(args: &[&str], file: &Path) -> Vec<Symbol> {
    let out = Command::new("nm")
        .args(args)
        .arg("-P")
        .arg(file)
        .output()
        .unwrap_or_else(|e| panic!("cannot run nm: {e}"));
    assert!(
        out.status.success(),
        "nm {args:?} {} failed: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|line| {
            // "[archive[member]: ]name type [value size]" (the prefix with -A).
            let (member, rest) = match line.split_once("]: ") {
                Some((file, rest)) => (file.rsplit_once('[').map_or("", |(_, m)| m), rest),
                None => ("", line),
            };
            let mut fields = rest.split_whitespace();
            let name = fields.next()?;
            let kind = fields.next()?.chars().next()?;
            Some(Symbol {
                member: member.to_owned(),
                name: name.to_owned(),
                kind,
            })
        })
        .collect()
}

/// What the bare archive may take from the C library; anything else it needs undefined means a
/// dependency firmware may not have. Update this list only for a reason written in
/// docs/embedded.md.
const BARE_LIBC: &[&str] = &[
    "abort",
    "free",
    "malloc",
    "posix_memalign",
    "memcpy",
    "memmove",
    "memset",
    "memcmp",
    "bcmp",
];

/// True for a symbol of Rust's std, an unwinder, threads or files.
fn std_only(name: &str) -> bool {
    // Mangled std paths: legacy `_ZN3std..`, v0 `..C3std..` / `.._3std..` (crate root `std`).
    let std_path = ["_ZN3std", "C3std", "_3std"]
        .iter()
        .any(|p| name.contains(p));
    let runtime = [
        "_Unwind_",
        "__gcc_personality",
        "rust_eh_personality",
        "pthread_",
        "__cxa_",
        "__tls_get_addr",
        "open",
        "fopen",
        "write",
        "read",
        "dlsym",
    ]
    .iter()
    .any(|p| name == *p || (p.ends_with('_') && name.starts_with(p)));
    std_path || runtime
}

/// The one std-only name the prebuilt `compiler_builtins` of a stable toolchain mentions: it was
/// compiled with unwind tables, so some of its members (f128 and libm-style math rayq does not use)
/// point at the personality routine. A link pulls a member in only for a symbol it defines and
/// nothing else does, and `embedded_minimal_fits_its_size_budget` links without any unwinder;
/// `-Z build-std` on nightly removes even these (docs/embedded.md).
fn builtins_personality(s: &Symbol) -> bool {
    s.member.starts_with("compiler_builtins-") && s.name.ends_with("rust_eh_personality")
}

#[test]
#[cfg(all(target_os = "linux", target_arch = "x86_64"))]
fn bare_archive_references_no_std_symbols() {
    // The explicit target keeps binutils from handing the members (which embed LLVM bitcode) to its
    // LLVM plugin, which cannot read a newer LLVM's bitcode and then reports "no symbols".
    let symbols = nm_symbols(&["-A", "--target=elf64-x86-64"], bare_library());
    assert!(
        symbols.iter().any(|s| s.name == "rq_scene_build"),
        "nm found no rq_scene_build in the bare archive"
    );
    let symbols: Vec<&Symbol> = symbols
        .iter()
        .filter(|s| !builtins_personality(s))
        .collect();
    let bad: BTreeSet<String> = symbols
        .iter()
        .filter(|s| std_only(&s.name))
        .map(|s| format!("{} in {}", s.name, s.member))
        .collect();
    assert!(
        bad.is_empty(),
        "the bare archive mentions std-only symbols: {bad:?}"
    );
    let defined: BTreeSet<&str> = symbols
        .iter()
        .filter(|s| !matches!(s.kind, 'U' | 'w' | 'v'))
        .map(|s| s.name.as_str())
        .collect();
    let needed: BTreeSet<&str> = symbols
        .iter()
        .filter(|s| s.kind == 'U' && !defined.contains(s.name.as_str()))
        .map(|s| s.name.as_str())
        .collect();
    let unexpected: Vec<&&str> = needed.iter().filter(|n| !BARE_LIBC.contains(n)).collect();
    assert!(
        unexpected.is_empty(),
        "the bare archive needs symbols beyond {BARE_LIBC:?}: {unexpected:?}"
    );
}

#[test]
#[cfg(target_os = "linux")]
fn std_only_catches_what_it_must() {
    // The check above passes only if this filter works: show it on names it must catch.
    for name in [
        "_Unwind_Resume",
        "pthread_mutex_lock",
        "_ZN3std2io5stdio6_print17h0123456789abcdefE",
        "_RNvNtCs1234_3std2io5_print",
        "open",
    ] {
        assert!(std_only(name), "{name} slipped through");
    }
    for name in ["rq_scene_build", "rust_begin_unwind", "memcpy", "readme"] {
        assert!(!std_only(name), "{name} is not std-only");
    }
}

#[test]
fn c_embedded() {
    let dir = scratch("embedded");
    let source = root().join("c_tests/embedded.c");
    let flags = [&["-g"], sanitizer_flags()].concat();
    let exe = build_program_with(
        &dir,
        "embedded",
        &source,
        &flags,
        &[bare_library().as_os_str(), OsStr::new("-lm")],
    );
    check_c_test_run("embedded", &run_program(&exe, &dir, &[]));
}

/// The stripped size in bytes that examples/embedded_minimal.c may reach when linked with the bare
/// archive and nothing but the C library (x86_64 Linux, gcc 12, Rust 1.95: 235 872 bytes when
/// first recorded; 252 256 after the grid's slab walk for long slivers, budget raised to 265 000;
/// 301 408 with the exact three-stage test and the new kd-tree, raised to 315 000; 317 792 with
/// scenes of several geometries (the conditions' path through every walk, the selection shared with
/// `rq_scene_set_vertices`) and the grid of issue 13, raised to 334 000; 346 464 at stop 21 with the
/// lean kd-tree walk and the filter that first tries the scene's bound, inline in every walk (out
/// of line, the program stays at 334 176 bytes but the rays take 1.01–1.29× the time: measured),
/// raised to 364 000; 362 848 at stop 22 with empty-block skipping; 395 616 at stop 23 with nested
/// grids in heavy cells — the walk's one cold copy per query kind, the run-time-axes kernel it uses,
/// the nested build — raised to 407 000; 387 424 at stop 27, 412 000 at stop 28 with the filter's
/// window check inline in every walk (out of line, 8 192 bytes less and the rays as slow as without
/// it: measured), raised to 428 000; 416 096 at stop 33, whose AVX walks this build leaves out;
/// 424 288 at stop 42; 428 384 at stop 43 with the selector's clock, its timed check and the
/// re-check of a kd-tree in `rq_scene_update` (one page more), raised to 450 000).
/// To raise it on purpose: run
/// `cargo test --test c_api embedded_minimal -- --nocapture`, note the size it prints, set this to
/// about 5 % above it, and update docs/embedded.md.
const MINIMAL_PROGRAM_BUDGET: u64 = 450_000;

#[test]
#[cfg(all(target_os = "linux", target_arch = "x86_64"))]
fn embedded_minimal_fits_its_size_budget() {
    let dir = scratch("embedded_minimal");
    let source = root().join("examples/embedded_minimal.c");
    let link: Vec<&OsStr> = [
        bare_library().as_os_str(),
        OsStr::new("-Wl,--gc-sections"),
        OsStr::new("-s"),
        // The C library only: no libgcc_s (unwinder), libpthread, libdl, libm.
        OsStr::new("-nodefaultlibs"),
        OsStr::new("-lc"),
    ]
    .to_vec();
    let exe = build_program_with(
        &dir,
        "embedded_minimal",
        &source,
        &["-Os", "-ffunction-sections", "-fdata-sections"],
        &link,
    );
    let ran = run_program(&exe, &dir, &[]);
    assert!(
        ran.success && ran.stdout.contains("embedded_minimal: hit"),
        "{}",
        ran.describe("examples/embedded_minimal.c failed")
    );
    let size = fs::metadata(&exe).expect("stat").len();
    let archive = fs::metadata(bare_library()).expect("stat").len();
    eprintln!("embedded_minimal: {size} bytes stripped (budget {MINIMAL_PROGRAM_BUDGET}); archive {archive} bytes");
    assert!(
        size <= MINIMAL_PROGRAM_BUDGET,
        "examples/embedded_minimal.c is {size} bytes stripped, over its budget of \
         {MINIMAL_PROGRAM_BUDGET}: find what grew, or raise MINIMAL_PROGRAM_BUDGET on purpose"
    );
}

/// The most stack one query (closest hit or any hit, grid or kd-tree) may use, in bytes, as
/// c_tests/stack_use.c measures it. The kd-tree's fixed traversal stack alone is 64 × 12 bytes.
/// To change it on purpose: run `cargo test --test c_api c_stack_use -- --nocapture`, and update
/// this and docs/embedded.md.
const QUERY_STACK_BUDGET: usize = 4096;

#[test]
#[cfg(target_os = "linux")]
fn c_stack_use() {
    let dir = scratch("stack_use");
    let source = root().join("c_tests/stack_use.c");
    // No sanitizers: they move locals to a heap of their own and change every frame.
    let exe = build_program_with(
        &dir,
        "stack_use",
        &source,
        &["-O2"],
        &[
            bare_library().as_os_str(),
            OsStr::new("-lpthread"),
            OsStr::new("-lm"),
        ],
    );
    let ran = run_program(&exe, &dir, &[]);
    check_c_test_run("stack_use", &ran);
    let used: usize = ran
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("stack_use: query "))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("{}", ran.describe("no stack figure printed")));
    assert!(
        used <= QUERY_STACK_BUDGET,
        "a query used {used} bytes of stack, over the budget of {QUERY_STACK_BUDGET}"
    );
}

#[test]
#[cfg(target_os = "linux")]
fn plugin_exports_only_rq_symbols() {
    let exported = nm_symbols(&["-D", "--defined-only"], plugin_library());
    assert!(
        exported.iter().any(|s| s.name == "rq_scene_build"),
        "the plugin exports no rq_scene_build"
    );
    let foreign: Vec<&str> = exported
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| !n.starts_with("rq_"))
        .collect();
    assert!(
        foreign.is_empty(),
        "the plugin exports symbols other than rq_*: {foreign:?}"
    );
}

#[test]
#[cfg(target_os = "linux")]
fn c_plugin() {
    let dir = scratch("plugin");
    // Two files, as two plugins would ship their own copy.
    let a = dir.join("plugin_a.so");
    let b = dir.join("plugin_b.so");
    fs::copy(plugin_library(), &a).expect("copy plugin a");
    fs::copy(plugin_library(), &b).expect("copy plugin b");
    let defines = [
        format!("-DRQ_PLUGIN_A=\"{}\"", a.display()),
        format!("-DRQ_PLUGIN_B=\"{}\"", b.display()),
    ];
    let mut flags = vec!["-g"];
    flags.extend_from_slice(sanitizer_flags());
    flags.extend(defines.iter().map(String::as_str));
    let exe = build_program_with(
        &dir,
        "plugin",
        &root().join("c_tests/plugin.c"),
        &flags,
        &[OsStr::new("-ldl")],
    );
    check_c_test_run("plugin", &run_program(&exe, &dir, &[]));
}

#[test]
fn example_pathtrace() {
    let teapot = root().join("scenes/teapot.obj");
    let teapot = teapot.to_str().expect("UTF-8 path");
    let dir = scratch("example_pathtrace");
    let exe = build_program(
        &dir,
        "pathtrace",
        &root().join("examples/pathtrace.c"),
        &["-DRQ_WITH_OBJ"],
    );
    // Every way of choosing the structure traces the same hits, so writes the same image; the
    // unknown budget reports its passes and may switch structures between them.
    let mut images = Vec::new();
    for mode in ["known", "unknown", "grid", "kdtree"] {
        let out = format!("{mode}.ppm");
        let ran = run_program(
            &exe,
            &dir,
            &[teapot, &out, "48", "36", "6", "--budget", mode],
        );
        assert!(
            ran.success,
            "{}",
            ran.describe(&format!("pathtrace --budget {mode} failed"))
        );
        for needle in ["report (", "outcome", "break-even W*", "rays:"] {
            assert!(
                ran.stdout.contains(needle),
                "{}",
                ran.describe(&format!(
                    "pathtrace --budget {mode} did not print {needle:?}"
                ))
            );
        }
        let (w, h, pixels) = read_ppm(&dir.join(&out));
        assert_eq!((w, h, pixels.len()), (48, 36, 48 * 36 * 3));
        images.push((mode, pixels));
    }
    for (mode, pixels) in &images[1..] {
        assert!(
            pixels == &images[0].1,
            "--budget {mode} and --budget known images differ"
        );
    }
    // The picture is not blank: the teapot and the sky differ.
    let first = &images[0].1;
    assert!(first.chunks(3).any(|p| p != &first[..3]), "a uniform image");
    // Bad command lines: a usage message and a non-zero exit.
    for args in [
        &[teapot][..],
        &[teapot, "x.ppm", "0", "4", "1"],
        &[teapot, "x.ppm", "8", "8", "1", "--budget", "octree"],
    ] {
        let ran = run_program(&exe, &dir, args);
        assert!(
            !ran.success && ran.stderr.contains("usage"),
            "{}",
            ran.describe("a bad command line was accepted")
        );
    }
}
