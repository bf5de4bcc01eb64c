//! A mutation fuzzer over the shipped scenes (issue 22): every number in
//! every scene file, one at a time, replaced by values at and past the
//! edges (0, -1, tiny, huge, NaN, infinity, the integer limits); each
//! mutated scene is parsed, validated and built. Loading must return a
//! scene or an error naming a field, never panic.
//!
//! Scenes whose build runs a simulation (smoke, dunes) are skipped (a
//! mutated setting means a new simulation; their settings have their own
//! stress tests in `tests/smoke.rs` and `tests/desert.rs`), and so is any
//! scene whose build takes over `SLOW`: the fuzzer is about validation.
//! `cargo test --release --test fuzz -- --nocapture` prints the executions.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use toml::Value;

const SLOW: Duration = Duration::from_millis(300);

/// The values a number is replaced by.
fn replacements(v: &Value) -> Vec<Value> {
    match v {
        Value::Integer(_) => {
            [0i64, -1, 1, 1 << 31, (1 << 32) - 1, 1 << 40, -(1 << 31)].iter().map(|&i| Value::Integer(i)).collect()
        }
        Value::Float(_) => [0.0, -1.0, 1e-30, -1e-30, 1e30, 3e38, -3e38, f64::NAN, f64::INFINITY, f64::NEG_INFINITY]
            .iter()
            .map(|&f| Value::Float(f))
            .collect(),
        _ => Vec::new(),
    }
}

/// Paths (as index chains) to every number in `v`.
fn numbers(v: &Value, path: &mut Vec<PathPart>, out: &mut Vec<Vec<PathPart>>) {
    match v {
        Value::Integer(_) | Value::Float(_) => out.push(path.clone()),
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                path.push(PathPart::Index(i));
                numbers(x, path, out);
                path.pop();
            }
        }
        Value::Table(t) => {
            for (k, x) in t {
                path.push(PathPart::Key(k.clone()));
                numbers(x, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

#[derive(Clone, Debug)]
enum PathPart {
    Key(String),
    Index(usize),
}

fn at<'a>(v: &'a mut Value, path: &[PathPart]) -> &'a mut Value {
    path.iter().fold(v, |v, p| match p {
        PathPart::Key(k) => &mut v[k.as_str()],
        PathPart::Index(i) => &mut v[*i],
    })
}

/// Whether a scene runs a simulation as it loads (smoke or dunes): a
/// cache may make its first build fast, but every mutation of its
/// settings would simulate again.
fn simulates(v: &Value) -> bool {
    let any = |list: &str, key: &str| {
        v.get(list).and_then(|l| l.as_array()).is_some_and(|a| a.iter().any(|x| x.get(key).is_some()))
    };
    any("volume", "smoke") || any("terrain", "dunes")
}

fn build(value: &Value, base: &Path) -> std::thread::Result<Result<(), String>> {
    catch_unwind(AssertUnwindSafe(|| {
        let file: slicelight::scene::SceneFile = match value.clone().try_into() {
            Ok(f) => f,
            Err(e) => return Err(format!("{e}")),
        };
        slicelight::scene::build(&file, base).map(|_| ()).map_err(|e| format!("{e:#}"))
    }))
}

/// The shipped scenes the fuzzers mutate (those `keep` takes), each edited
/// by `edit` first: those that build, in under `SLOW`, without a
/// simulation (the others are named on stdout with why).
fn fuzzable_scenes(dir: &Path, edit: impl Fn(&mut Value), keep: impl Fn(&Value) -> bool) -> Vec<(PathBuf, Value)> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for path in paths {
        let mut scene: Value = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        if !keep(&scene) {
            continue;
        }
        edit(&mut scene);
        // A simulating scene is left out before it is built: its build
        // would run the simulation only to be skipped (the smoke scenes'
        // and the dunes' were most of this triage's time).
        if simulates(&scene) {
            println!("{}: skipped (it simulates as it loads)", path.display());
            continue;
        }
        let t = Instant::now();
        let ok = build(&scene, dir);
        if t.elapsed() > SLOW || !matches!(ok, Ok(Ok(()))) {
            println!("{}: skipped ({:?}, {:?})", path.display(), t.elapsed(), ok.map(|r| r.is_ok()));
            continue;
        }
        out.push((path, scene));
    }
    out
}

/// Every single-number mutation of `scene`: the path to a number and the
/// value that replaces it.
fn mutations(scene: &Value) -> Vec<(Vec<PathPart>, Value)> {
    let mut paths_to_numbers = Vec::new();
    numbers(scene, &mut Vec::new(), &mut paths_to_numbers);
    let mut out = Vec::new();
    for p in paths_to_numbers {
        for r in replacements(at(&mut scene.clone(), &p)) {
            out.push((p.clone(), r));
        }
    }
    out
}

/// `scene` with the number at `path` replaced by `value`.
fn mutated(scene: &Value, path: &[PathPart], value: &Value) -> Value {
    let mut v = scene.clone();
    *at(&mut v, path) = value.clone();
    v
}

/// Whether a scene holds a glass object (its build traces the light
/// through the glass: most of the build fuzzer's time).
fn has_glass(v: &Value) -> bool {
    v.get("object").and_then(|o| o.as_array()).is_some_and(|objects| {
        objects.iter().any(|o| o.get("material").and_then(|m| m.get("kind")).and_then(|k| k.as_str()) == Some("glass"))
    })
}

// The build fuzzer in two tests, the scenes with glass and the rest (26 s
// and 16 s alone on 2 cores; 40 s as one test): the same cases.
#[test]
fn mutated_scene_files_with_glass_load_or_fail_with_an_error_never_a_panic() {
    own_pool(|| build_fuzzer(true));
}

#[test]
fn mutated_scene_files_without_glass_load_or_fail_with_an_error_never_a_panic() {
    own_pool(|| build_fuzzer(false));
}

/// Runs `f` on a thread pool of its own. The fuzzers run side by side in
/// one process; on rayon's shared pool, a scene build's own parallel work
/// (the caustics' exit rays, the BVH) queued behind the other fuzzer's
/// thousands of cases, and a triage build waited 12-25 s for a thread: over
/// `SLOW`, so CI left a different glass scene out of each run.
fn own_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new().build().expect("a thread pool").install(f)
}

/// Every mutation of every fuzzable scene with glass (`glass`) or without
/// is parsed, validated and built: a scene or an error, never a panic.
fn build_fuzzer(glass: bool) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    // Panics are expected to be caught here; keep their messages quiet.
    std::panic::set_hook(Box::new(|_| {}));
    let scenes = fuzzable_scenes(&dir, |_| {}, |v| has_glass(v) == glass);
    let cases: Vec<_> = scenes
        .iter()
        .flat_map(|(path, original)| mutations(original).into_iter().map(move |m| (path, original, m)))
        .collect();
    // Every build on every core (each is independent; about 18 000 of them).
    use rayon::prelude::*;
    enum Outcome {
        Built,
        Refused,
        Panicked(String),
    }
    let outcomes: Vec<Outcome> = cases
        .par_iter()
        .map(|(path, original, (p, r))| {
            let t = Instant::now();
            let outcome = match build(&mutated(original, p, r), &dir) {
                Ok(Ok(())) => Outcome::Built,
                Ok(Err(_)) => Outcome::Refused,
                Err(_) => Outcome::Panicked(format!("{} {p:?} = {r}", path.display())),
            };
            assert!(t.elapsed() < Duration::from_secs(30), "{} {p:?} = {r}: {:?}", path.display(), t.elapsed());
            outcome
        })
        .collect();
    let executions = outcomes.len();
    let refused = outcomes.iter().filter(|o| matches!(o, Outcome::Refused)).count();
    let panics: Vec<String> = outcomes
        .into_iter()
        .filter_map(|o| match o {
            Outcome::Panicked(what) => Some(what),
            Outcome::Built | Outcome::Refused => None,
        })
        .collect();
    let _ = std::panic::take_hook();
    println!("{executions} mutated scenes built, {refused} refused with an error, {} panics", panics.len());
    assert!(executions > 1000, "{executions}");
    assert!(panics.is_empty(), "{} panics:\n{}", panics.len(), panics.join("\n"));
}

/// Seconds the rendering fuzzer runs (its coverage is printed); the
/// environment's `SLICELIGHT_FUZZ_SECONDS` runs it longer. 24 s on every
/// core covers more cases than the 60 s on one core it had until
/// 2026-12-06 (measured alone on 2 cores: 528 cases in 27.6 s with 25 s,
/// 454 in 61 s before).
fn render_budget() -> Duration {
    let s = std::env::var("SLICELIGHT_FUZZ_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(24);
    Duration::from_secs(s)
}

/// Renders the rendering fuzzer makes at the least, however long they take.
const MIN_RENDERED: u64 = 100;

#[test]
fn mutated_scenes_that_load_render_finite() {
    own_pool(render_fuzzer)
}

fn render_fuzzer() {
    // The same mutations on every scene made 8 x 6 pixels, taken in a fixed
    // shuffled order for `render_budget()` and until `MIN_RENDERED` of them
    // have rendered: every scene that loads renders
    // (CPU backend) without a panic or an error and with finite pixels.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    std::panic::set_hook(Box::new(|_| {}));
    let small = |scene: &mut Value| {
        scene["camera"]["resolution"] = Value::Array(vec![Value::Integer(8), Value::Integer(6)]);
    };
    let scenes = fuzzable_scenes(&dir, small, |_| true);
    let mut cases = Vec::new();
    for (k, (_, original)) in scenes.iter().enumerate() {
        cases.extend(mutations(original).into_iter().map(|(p, r)| (k, p, r)));
    }
    // A fixed shuffle (an LCG), so every run covers the same cases first.
    let mut state = 0x2545_f491u64;
    for i in (1..cases.len()).rev() {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        cases.swap(i, (state >> 33) as usize % (i + 1));
    }
    let backend = slicelight::render::Backend::Cpu;
    let (mut tried, mut rendered, mut bad) = (0u64, 0u64, Vec::new());
    let clock = Instant::now();
    // `SLICELIGHT_FUZZ_SKIP=N` starts after the first N cases (a longer
    // exploration in pieces).
    let skip = std::env::var("SLICELIGHT_FUZZ_SKIP").ok().and_then(|s| s.parse().ok()).unwrap_or(0);
    // Cases in batches on every core, in the shuffled order: a run covers
    // the first batches, the same ones on any machine, as many as its
    // budget allows.
    use rayon::prelude::*;
    const BATCH: usize = 16;
    for batch in cases[skip.min(cases.len())..].chunks(BATCH) {
        // Past the budget only until the fewest renders the test asks
        // (a loaded machine takes longer; it does not cover less).
        if clock.elapsed() > render_budget() && rendered >= MIN_RENDERED {
            break;
        }
        tried += batch.len() as u64;
        let outcomes: Vec<(bool, Option<String>)> = batch
            .par_iter()
            .map(|(k, p, r)| {
                let (path, original) = &scenes[*k];
                let v = mutated(original, p, r);
                let outcome = catch_unwind(AssertUnwindSafe(|| {
                    let file: slicelight::scene::SceneFile = v.clone().try_into().ok()?;
                    let data = slicelight::scene::build(&file, &dir).ok()?;
                    Some(slicelight::render::render_layers(&data, &backend, false).map(|r| r.image))
                }));
                let name = format!("{} {p:?} = {r}", path.display());
                match outcome {
                    Err(_) => (false, Some(format!("{name}: panic"))),
                    Ok(None) => (false, None),
                    Ok(Some(Err(e))) => (false, Some(format!("{name}: render error {e:#}"))),
                    Ok(Some(Ok(image))) => {
                        let finite = image.iter().all(|p| p.truncate().is_finite());
                        (true, (!finite).then(|| format!("{name}: a pixel not finite")))
                    }
                }
            })
            .collect();
        for (was_rendered, problem) in outcomes {
            rendered += was_rendered as u64;
            bad.extend(problem);
        }
    }
    let _ = std::panic::take_hook();
    println!(
        "{tried} of {} mutations tried in {:?}, {rendered} rendered; {} bad",
        cases.len(),
        clock.elapsed(),
        bad.len()
    );
    assert!(rendered >= MIN_RENDERED, "{rendered} of {tried} mutated scenes rendered");
    assert!(bad.is_empty(), "{} bad:\n{}", bad.len(), bad.join("\n"));
}
