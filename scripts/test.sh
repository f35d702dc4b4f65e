#!/usr/bin/env bash
# The whole test suite: unit + integration tests of every workspace crate, formatting and lints.
# Assumes scripts/setup.sh has run (README's command 2 runs both).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
export CARGO_TERM_COLOR="${CARGO_TERM_COLOR:-never}"
# Mesa's Vulkan loader complains on every device creation when this is unset.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
# A clean build of every test binary with incremental caches and line tables took ~6 GB of
# target/ and a CI machine ran out of disk while linking (stop 70). The suite is built once per
# run, so neither pays: no incremental cache, no debug info (panic messages keep file:line).
# A developer's own `cargo test` keeps both.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
export CARGO_PROFILE_DEV_DEBUG="${CARGO_PROFILE_DEV_DEBUG:-false}"
echo "== disk before the build: $(df -h --output=avail . | tail -1 | tr -d ' ') free"
echo "== cargo fmt --check"
cargo fmt --all --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== cargo test"
cargo test --workspace --locked
echo "== disk after the build: $(df -h --output=avail . | tail -1 | tr -d ' ') free, target/ $(du -sh target 2>/dev/null | cut -f1)"
echo "== all checks passed"
