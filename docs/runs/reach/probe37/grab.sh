#!/bin/bash
# copy scratch-line-s1's policy when it is saved at iteration 1500
R=/work/runs37/scratch-line-s1; O=/work/runs37/s1-policy-1500
while true; do
  it=$(python3 -c "import json;print(json.load(open('$R/policy.json'))['payload']['counters']['iteration'])" 2>/dev/null)
  if [ "$it" = "1500" ]; then
    mkdir -p $O; cp $R/policy.json $O/; w=$(python3 -c "import json;print(json.load(open('$O/policy.json'))['weights_file'])"); cp $R/$w $O/ && echo "grabbed $it $w" && exit 0
  fi
  [ -n "$it" ] && [ "$it" -gt 1500 ] && echo "missed ($it)" && exit 1
  sleep 5
done
