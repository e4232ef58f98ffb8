#!/usr/bin/env bash
# Populate the fuzz corpora (fuzz/corpus/<target>/, gitignored) with seeds:
#   gltf_import:                     the glTF samples in $GLTF_SAMPLES_DIR (default ../shared/gltf-samples),
#                                    read from there, as .gltf and converted to .glb
#   pack_from_bytes, pack_manifest:  the packs those samples cook to, one synthetic pack that uses
#                                    every manifest section, and the small packs `make cook` left in build/
# Re-running only adds or refreshes seeds; what the fuzzer found stays. Used by `make fuzz`.
set -euo pipefail
cd "$(dirname "$0")/.."
samples="${GLTF_SAMPLES_DIR:-../shared/gltf-samples}"
corpus=fuzz/corpus
seeds=build/fuzz-seeds
rm -rf "$seeds"
mkdir -p "$seeds/packs" "$seeds/gltf" "$corpus/pack_from_bytes" "$corpus/pack_manifest" "$corpus/gltf_import"
shopt -s nullglob
gltfs=("$samples"/*/*.gltf "$samples"/*/*.glb)
if [ ${#gltfs[@]} -eq 0 ]; then
  echo "fuzz_seed: no glTF samples under $samples; seeding with the synthetic pack only" >&2
fi
cargo run --offline --release -q -p cook_core --example fuzz_seeds -- "$seeds/packs" "$seeds/gltf" "${gltfs[@]}"
for p in build/*.pack; do
  # Big packs (a baked level) only slow the fuzzer down; the small ones cover the same format.
  if [ "$(stat -c %s "$p")" -le 262144 ]; then cp "$p" "$seeds/packs/cooked-$(basename "$p")"; fi
done
cp "$seeds"/packs/* "$corpus/pack_from_bytes/"
cp "$seeds"/packs/* "$corpus/pack_manifest/"
cp "$seeds"/gltf/* "$corpus/gltf_import/"
echo "fuzz_seed: $(ls "$seeds/packs" | wc -l) pack seeds, $(ls "$seeds/gltf" | wc -l) glTF seeds"
