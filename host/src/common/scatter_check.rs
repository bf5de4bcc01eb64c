//! The scatter self-check pass (kernel: `shader-crate/src/common/scatter_check.rs`):
//! fixed-point scatter accumulation under heavy contention, against its
//! closed form. It runs when asked for (`slicelight render --pass
//! scatter_check`, or a test); a scene never needs it.

use anyhow::{ensure, Result};
use indicatif::ProgressBar;
use slicelight_shaders::common::scatter_check::{scatter_check_invocation, ScatterCheckParams};
use slicelight_shaders::scatter::{decode, words_for, CpuAtomics};
use slicelight_shaders::types::CommonParams;

use crate::cpu::for_each_index;
use crate::passes::*;
use crate::scene::SceneData;

/// 7 x 4 x 2^16 invocations into 4 bins: 458 752 adds per bin, each of
/// 2^22 to 7 x 2^22 fixed-point units, so every bin's low word wraps over a
/// thousand times. The overflow bins' scale (2^45) puts their sums at
/// 1.6e19 units, past the 2^63 range.
pub const PARAMS: ScatterCheckParams = ScatterCheckParams {
    invocations: 7 * 4 * (1 << 16),
    bins: 4,
    scale: 16_777_216.0,
    overflow_scale: 35_184_372_088_832.0,
};

pub static CHECK_PARAMS: Resource = Resource {
    binding: 13,
    name: "scatter check parameters",
    kind: ResourceKind::Scene(|_| bytemuck::bytes_of(&PARAMS)),
};
/// The accumulation words: `words_for(2 bins)` u32s.
pub static CHECK_WORDS: Resource = Resource {
    binding: 14,
    name: "scatter check accumulators",
    kind: ResourceKind::Frame(|_| words_for(2 * PARAMS.bins) as u64 * 4),
};

pub struct ScatterCheck;

impl ScatterCheck {
    /// Checks the words against the closed form: every exact bin holds
    /// `invocations / bins`, every overflow bin is saturated, none rejected.
    fn verdict(words: &[u32]) -> Result<String> {
        let p = PARAMS;
        ensure!(words.len() == words_for(2 * p.bins) as usize, "{} accumulator words", words.len());
        ensure!(words[0] == 0, "{} contributions rejected", words[0]);
        let expected = (p.invocations / p.bins) as f64;
        for b in 0..p.bins as usize {
            let (v, saturated) = decode(words[1 + 2 * b], words[2 + 2 * b], p.scale);
            ensure!(!saturated && v == expected, "bin {b}: {v} (saturated: {saturated}), expected exactly {expected}");
        }
        for b in p.bins as usize..2 * p.bins as usize {
            let (_, saturated) = decode(words[1 + 2 * b], words[2 + 2 * b], p.overflow_scale);
            ensure!(saturated, "overflow bin {b} is not saturated: it wrapped");
        }
        Ok(format!(
            "{} invocations: {} bins exactly {expected}, {} overflow bins saturated",
            p.invocations, p.bins, p.bins
        ))
    }
}

impl Pass for ScatterCheck {
    fn name(&self) -> &'static str {
        "scatter_check"
    }
    fn kernel(&self) -> &'static str {
        "common::scatter_check::scatter_check_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![CHECK_PARAMS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CHECK_WORDS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }

    fn plan(&self, scene: &SceneData) -> Plan {
        if scene.requested_passes.iter().any(|p| p == self.name()) {
            Plan::run("requested: fixed-point scatter accumulation against its closed form", PARAMS.invocations as u64)
        } else {
            Plan::skip("a self-check; run it with --pass scatter_check")
        }
    }

    fn run_cpu(&self, _scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let mut words = Buffer::zeroed::<u32>(words_for(2 * PARAMS.bins) as usize);
        {
            let atomics = crate::cpu::as_atomics(words.as_mut_slice::<u32>());
            for_each_index(PARAMS.invocations, progress, |i| {
                scatter_check_invocation(i, &PARAMS, &mut CpuAtomics(atomics));
            });
        }
        frame.insert(&CHECK_WORDS, words);
    }

    fn report(&self, _scene: &SceneData, frame: &Frame) -> Result<Option<String>> {
        Self::verdict(frame.get::<u32>(&CHECK_WORDS)).map(Some)
    }

    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        let (g, c) = (gpu.get::<u32>(&CHECK_WORDS), cpu.get::<u32>(&CHECK_WORDS));
        let cpu_verdict = Self::verdict(c)?;
        Self::verdict(g)?;
        // Integer sums in any order: the two backends must agree bit for bit.
        ensure!(g == c, "GPU words {g:?} differ from CPU words {c:?}");
        Ok(format!("bit for bit; {cpu_verdict}"))
    }
}
