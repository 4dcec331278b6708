"""The discriminator's two sides in W-iteration windows: python3 discsides.py RUN/metrics.csv W

Over the rows that have `disc_demo_accuracy` (runs from the forty-third session on): mean accuracy, demo-side and
agent-side accuracy, mean demo and agent logits, style reward, and episode-weighted falls."""
import csv, sys

rows = [r for r in csv.DictReader(open(sys.argv[1])) if r.get("disc_demo_accuracy")]
W = int(sys.argv[2]) if len(sys.argv) > 2 else 100
keys = ["disc_accuracy", "disc_demo_accuracy", "disc_agent_accuracy", "disc_demo_logit", "disc_agent_logit", "style_reward"]
print("iterations      " + " ".join(f"{k.replace('disc_', ''):>15}" for k in keys) + "   falls")
for k in range(0, len(rows), W):
    c = rows[k : k + W]
    mean = lambda key: sum(float(r[key]) for r in c) / len(c)
    E = sum(float(r["episodes"] or 0) for r in c) or 1
    falls = sum(float(r["fall_fraction"] or 0) * float(r["episodes"] or 0) for r in c) / E
    print(f"{c[0]['iteration']:>6}-{c[-1]['iteration']:<6}  " + " ".join(f"{mean(x):15.3f}" for x in keys) + f"  {falls:.3f}")
