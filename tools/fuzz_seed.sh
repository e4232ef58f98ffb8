#!/usr/bin/env bash
# Populate the fuzz corpora (fuzz/corpus/<target>/, gitignored) with seeds:
#   gltf_import:                     the glTF samples in $GLTF_SAMPLES_DIR (default ../shared/gltf-samples),
#                                    read from there, and small scenes that use each glTF extension
#                                    the importer supports (tools/fuzz_gltf_ext_seeds.py), as .gltf
#                                    and converted to .glb
#   pack_from_bytes, pack_manifest:  the packs those cook to, one synthetic pack that uses every
#                                    manifest section, and the small packs `make cook` left in build/
#   level_toml:                      the project's levels and the levels the tests write
#                                    (tools/fuzz_level_seeds.py)
# Re-running only adds or refreshes seeds; what the fuzzer found stays. Used by `make fuzz`.
set -euo pipefail
cd "$(dirname "$0")/.."
samples="${GLTF_SAMPLES_DIR:-../shared/gltf-samples}"
corpus=fuzz/corpus
seeds=build/fuzz-seeds
rm -rf "$seeds"
mkdir -p "$seeds/packs" "$seeds/gltf" "$seeds/ext" "$seeds/levels" "$corpus/pack_from_bytes" "$corpus/pack_manifest" \
  "$corpus/gltf_import" "$corpus/level_toml"
python=python3
[ -x .venv/bin/python ] && python=.venv/bin/python
"$python" tools/fuzz_gltf_ext_seeds.py "$seeds/ext"
"$python" tools/fuzz_level_seeds.py "$seeds/levels"
shopt -s nullglob
# Big samples (a 3 MB terrain) only slow the fuzzer down (libFuzzer sizes its inputs by the largest
# in the corpus); the small ones cover the same format.
gltfs=()
for g in "$samples"/*/*.gltf "$samples"/*/*.glb; do
  if [ "$(stat -c %s "$g")" -le 262144 ]; then gltfs+=("$g"); fi
done
find "$corpus" -type f -size +256k -delete
if [ ${#gltfs[@]} -eq 0 ]; then
  echo "fuzz_seed: no glTF samples under $samples; seeding with the extension scenes and the synthetic pack only" >&2
fi
gltfs+=("$seeds"/ext/*.gltf)
cargo run --offline --release -q -p cook_core --example fuzz_seeds -- "$seeds/packs" "$seeds/gltf" "${gltfs[@]}"
for p in build/*.pack; do
  # Big packs (a baked level) only slow the fuzzer down; the small ones cover the same format.
  if [ "$(stat -c %s "$p")" -le 262144 ]; then cp "$p" "$seeds/packs/cooked-$(basename "$p")"; fi
done
cp "$seeds"/packs/* "$corpus/pack_from_bytes/"
cp "$seeds"/packs/* "$corpus/pack_manifest/"
cp "$seeds"/gltf/* "$corpus/gltf_import/"
cp "$seeds"/levels/* "$corpus/level_toml/"
echo "fuzz_seed: $(ls "$seeds/packs" | wc -l) pack seeds, $(ls "$seeds/gltf" | wc -l) glTF seeds ($(ls "$seeds/gltf" | grep -c '^ext_') with extensions), $(ls "$seeds/levels" | wc -l) level seeds"
