"""The discriminator's two sides in W-iteration windows from iteration FROM on, for several runs side by side:
python3 sides_from.py W FROM name=RUN/metrics.csv ...

Per window: mean accuracy, demo-side and agent-side accuracy, style reward (means over the rows) and
episode-weighted falls."""
import csv, sys

W, FROM = int(sys.argv[1]), int(sys.argv[2])
keys = ["disc_accuracy", "disc_demo_accuracy", "disc_agent_accuracy", "style_reward"]
for spec in sys.argv[3:]:
    name, path = spec.split("=", 1)
    rows = [r for r in csv.DictReader(open(path)) if int(r["iteration"]) >= FROM and r.get("disc_demo_accuracy")]
    print(f"{name}: iterations, accuracy, demo side, agent side, style, falls")
    for k in range(0, len(rows), W):
        c = rows[k : k + W]
        mean = lambda key: sum(float(r[key]) for r in c) / len(c)
        E = sum(float(r["episodes"] or 0) for r in c) or 1
        falls = sum(float(r["fall_fraction"] or 0) * float(r["episodes"] or 0) for r in c) / E
        cells = " ".join(f"{mean(x):.3f}" for x in keys)
        print(f"  {c[0]['iteration']}-{c[-1]['iteration']} ({len(c)} its) {cells} {falls:.3f}")
