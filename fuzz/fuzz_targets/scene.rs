//! A scene file's text: TOML parsing, keyframes, validation and the build
//! (meshing, tables' set-up), as `slicelight render` loads it. An error is
//! the expected answer to most inputs; a panic, a hang or an allocation
//! over the bound is a finding.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    let Ok(text) = std::str::from_utf8(bytes) else { return };
    // Scenes that simulate as they load (smoke, dunes, the cloud automaton)
    // run for as long as their settings ask, within their limits: seconds,
    // which libFuzzer would report as hangs. Their settings' parsing and
    // validation are fuzzed through tests/fuzz.rs's mutations instead.
    if ["smoke", "dunes", "automaton", "ripples"].iter().any(|w| text.contains(w)) {
        return;
    }
    let _ = slicelight::scene::from_text(text, Path::new("fuzz/corpus/scene/scene.toml"));
});
