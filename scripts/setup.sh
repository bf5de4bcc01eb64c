#!/usr/bin/env bash
# Installs what slicelight needs and a fresh machine lacks: the pinned Rust-GPU
# nightly (from rust-toolchain.toml) and, on Debian/Ubuntu, a Vulkan loader
# with lavapipe (Mesa's Vulkan device on the CPU) so the GPU backend and the
# GPU-vs-CPU tests run without a GPU. Safe to run again: it skips what is there.
set -euo pipefail
cd "$(dirname "$0")/.."

toolchain=$(sed -n 's/^channel *= *"\(.*\)"/\1/p' rust-toolchain.toml)
if ! rustup toolchain list | grep -q "^$toolchain"; then
    echo "setup: installing Rust toolchain $toolchain" >&2
    rustup toolchain install  # installs what rust-toolchain.toml names, with its components
fi

have_vulkan() {
    ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1 && ldconfig -p | grep -q 'libvulkan\.so\.1'
}
if ! have_vulkan; then
    if command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing the Vulkan loader and lavapipe (mesa-vulkan-drivers)" >&2
        sudo_cmd=""
        [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
        $sudo_cmd apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
    else
        echo "setup: no Vulkan driver found and no apt-get; install a Vulkan driver (or use --backend cpu)" >&2
    fi
fi
