"""Windows of a run's metrics.csv: python3 windows.py RUN/metrics.csv [ITERATIONS_PER_WINDOW].

Per window: iterations, samples at its end, episode-weighted episode length, falls, rest-start (task-start) falls,
reach from rest starts and from all starts; mean disc accuracy, style, task and imitation reward, samples/s."""
import csv,sys
rows=list(csv.DictReader(open(sys.argv[1])))
w=int(sys.argv[2]) if len(sys.argv)>2 else max(1,len(rows)//10)
def f(r,k):
    try: return float(r[k])
    except: return float('nan')
print("its        samples  len    fall  tsfall reach reachA disc  style task  imit  sps")
for i in range(0,len(rows),w):
    ch=rows[i:i+w]; E=sum(f(r,'episodes') for r in ch) or 1
    ew=lambda k: sum(f(r,k)*f(r,'episodes') for r in ch if f(r,k)==f(r,k))/E
    m=lambda k: sum(f(r,k) for r in ch)/len(ch)
    print(f"{ch[0]['iteration']:>4}-{ch[-1]['iteration']:<5} {f(ch[-1],'samples')/1e6:6.2f}M {ew('mean_episode_length'):6.1f} {ew('fall_fraction'):.3f} {ew('task_start_fall_fraction'):.3f} {ew('reach_rate'):.3f} {ew('reach_rate_all'):.3f} {m('disc_accuracy'):.3f} {m('style_reward'):.3f} {m('task_reward'):.3f} {m('reward_imitation'):.3f} {m('samples_per_s'):.0f}")
