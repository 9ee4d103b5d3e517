//! The C conformance suite. Builds the static library once (a nested `cargo rustc` into its own target
//! directory), compiles every program in `c_tests/` and the C examples with the platform's C compiler
//! (found by the `cc` crate) as strict C99 with every warning an error and, where the compiler has
//! them, AddressSanitizer and UndefinedBehaviorSanitizer, links them with the library and runs them.
//! A C program reports failures on stderr and exits non-zero; this file turns that into a failed test
//! that shows the program's output.
//!
//! `RAYQ_C_NO_SANITIZERS=1` turns the sanitizers off (for compilers or machines where they misbehave).

use std::collections::BTreeSet;
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
    "calibration",
    "hostile_mesh",
    "lifecycle",
    "obj",
    "precision",
    "queries",
    "report",
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
    // A target directory of its own: the outer `cargo test` may still hold the lock on the main one.
    // CARGO_TARGET_TMPDIR is `<target dir>/tmp`, so this honours a custom CARGO_TARGET_DIR.
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let target_dir = tmp.parent().unwrap_or(tmp).join("c-api");
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(root())
        .args([
            "rustc",
            "--lib",
            "--crate-type",
            "staticlib",
            "--features",
            "capi,obj",
            "--target",
            TARGET,
        ])
        .arg("--target-dir")
        .arg(&target_dir);
    let started = Instant::now();
    let out = cmd
        .output()
        .map_err(|e| format!("cannot run {cmd:?}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "building the static library failed ({}):\n{cmd:?}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let name = if TARGET.contains("msvc") {
        "rayq.lib"
    } else {
        "librayq.a"
    };
    let lib = target_dir.join(TARGET).join("debug").join(name);
    if !lib.is_file() {
        return Err(format!(
            "cargo succeeded but {} does not exist",
            lib.display()
        ));
    }
    eprintln!(
        "c_api: static library ready in {:.1} s: {}",
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
    let exe = dir.join(exe_name(name));
    let mut cmd = compiler(false);
    cmd.args(STRICT_C99)
        .arg("-g")
        .args(sanitizer_flags())
        .args(defines)
        .arg("-I")
        .arg(root().join("include"))
        .arg("-I")
        .arg(root().join("c_tests"))
        .arg(source)
        .arg("-o")
        .arg(&exe)
        .arg(library())
        .args(native_libs());
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
    let ran = run_program(&exe, &dir, &[]);
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
fn c_hostile_mesh() {
    run_c_test("hostile_mesh");
}

#[test]
fn c_lifecycle() {
    run_c_test("lifecycle");
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
}
