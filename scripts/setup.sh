#!/usr/bin/env bash
# Installs what slicelight needs and a fresh machine lacks: the pinned Rust-GPU
# nightly (from rust-toolchain.toml) and, on Debian/Ubuntu, a Vulkan loader
# with lavapipe (Mesa's Vulkan device on the CPU) so the GPU backend and the
# GPU-vs-CPU tests run without a GPU, a C compiler where there is none, the
# DejaVu fonts for the benchmark's plots, and the X11 libraries and tools of
# the viewer and its tests (Xvfb, xdotool, xwd). Safe to run again: it skips
# what is there.
set -euo pipefail
cd "$(dirname "$0")/.."

toolchain=$(sed -n 's/^channel *= *"\(.*\)"/\1/p' rust-toolchain.toml)
if ! rustup toolchain list | grep -q "^$toolchain"; then
    echo "setup: installing Rust toolchain $toolchain" >&2
    rustup toolchain install  # installs what rust-toolchain.toml names, with its components
fi
# A toolchain installed before rustfmt and clippy joined rust-toolchain.toml lacks them.
for component in rustfmt clippy; do
    rustup component list --toolchain "$toolchain" --installed | grep -q "^$component" \
        || rustup component add --toolchain "$toolchain" "$component"
done

have_vulkan() {
    ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1 && ldconfig -p | grep -q 'libvulkan\.so\.1'
}
missing=()
have_vulkan || missing+=(mesa-vulkan-drivers libvulkan1)
# A C compiler: Rust links with it, and the OpenVDB reader's Blosc
# decompressor (blosc-src) is C built at compile time.
command -v cc >/dev/null 2>&1 || missing+=(gcc libc6-dev)
# The font of `slicelight bench`'s plot labels.
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || missing+=(fonts-dejavu-core)
# `slicelight view`'s window (X11, loaded at run time) and its tests: an X
# server without a screen (Xvfb), real key and mouse events (xdotool) and
# window screenshots (xwd, in x11-apps).
for pkg in libx11-6 libx11-xcb1 libxcursor1 libxrandr2 libxi6 libxkbcommon-x11-0 xvfb xdotool x11-apps; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
    if command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing ${missing[*]}" >&2
        sudo_cmd=""
        [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
        $sudo_cmd apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
    else
        echo "setup: missing ${missing[*]} and no apt-get: install a Vulkan driver (or use --backend cpu) and the DejaVu fonts" >&2
    fi
fi
