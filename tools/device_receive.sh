#!/usr/bin/env bash
# On the GPU machine: keep the staged part(s) this call carries (.stage/call-NN, made by
# tools/device_stage.py) in /tmp/qdil-stage; once every part is there and the whole matches
# its checksum, unpack it into /tmp/site, where PYTHONPATH=/tmp/site:src finds qdil's needs.
# Exit status: 0 staged (now or by an earlier call), 3 parts still missing, 1 an error.
set -euo pipefail
store=${QDIL_STAGE_STORE:-/tmp/qdil-stage}  # (the test points both elsewhere)
site=${QDIL_STAGE_SITE:-/tmp/site}
mkdir -p "$store"
for folder in .stage/call-*; do
  [ -d "$folder" ] && cp "$folder"/part-* "$folder"/plan.json "$store"/
done
if [ ! -f "$store/plan.json" ]; then
  echo "no staged part here or in $store: carry .stage/call-01 (python tools/device_stage.py)"
  exit 1
fi
read -r parts sha < <(python3 -c 'import json, sys; p = json.load(open(sys.argv[1]))
print(p["parts"], p["sha256"])' "$store/plan.json")
if [ -f "$site/.staged-$sha" ]; then
  echo "staged already in $site"
  exit 0
fi
have=$(find "$store" -name 'part-*' | wc -l)
if [ "$have" -lt "$parts" ]; then
  echo "$have of $parts parts in $store: carry the next .stage/call-NN while the machine is warm"
  exit 3
fi
cat "$store"/part-* > "$store/site.tar.xz"
if [ "$(sha256sum "$store/site.tar.xz" | cut -d' ' -f1)" != "$sha" ]; then
  echo "the parts in $store do not make the staged whole (sha256 differs): stage again"
  rm -f "$store"/part-* "$store/site.tar.xz"
  exit 1
fi
rm -rf "$site"
mkdir -p "$site"
xz -dc "$store/site.tar.xz" | tar -x -C "$site"
rm -f "$store/site.tar.xz"
touch "$site/.staged-$sha"
echo "staged $parts parts into $site: run with PYTHONPATH=$site:src"
