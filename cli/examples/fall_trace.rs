//! Diagnostic: what goes wrong before a `[env.gait]` policy falls on a long walk. Plays the run's
//! policy with mean actions from the task's standing start (as `lhm eval --from-rest`) on the
//! unseen tasks whose first object is at least MIN_DISTANCE m away, and writes one CSV row per
//! control step while the gait walks: the character's centre-of-mass velocity and offset over its
//! stance foot, its pelvis tilt, each against the gait reference's (aligned to the character, as
//! the base's feedback sees them), whether the character's lower foot is the reference's stance
//! foot, each foot's velocity forward and sideways while it is on the ground (slip; empty in the
//! air), the hips' pitch, the knees and the ankles' pitch against the reference's, and the
//! episode's end (the step it fell, or -1).
//! `cargo run --release -p lhm-cli --example fall_trace -- RUN_DIR [MIN_DISTANCE] [SEEDS] > trace.csv`
//! (RUN_DIR holds `config.toml` and `checkpoint` or `policy`).
#[path = "shared/gait_run.rs"]
mod gait_run;
use gait_run::GaitRun;
use lhm_actor::eval::{EvalSetup, GaitStart};
use lhm_scenes::Split;
use lhm_sim::fidelity::joint_angles;
use lhm_sim::gait::{aligned_to, balance, rotation_error, Rig, CONTACT_HEIGHT};
use lhm_sim::obs::HeadingFrame;
use std::path::PathBuf;
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: fall_trace RUN_DIR [MIN_DISTANCE] [SEEDS]")?,
    );
    let min_distance: f32 = args.next().map_or(Ok(3.0), |s| s.parse())?;
    let seeds: u64 = args.next().map_or(Ok(4), |s| s.parse())?;
    let stem = if dir.join("checkpoint.json").is_file() {
        "checkpoint"
    } else {
        "policy"
    };
    let GaitRun {
        config,
        learner,
        model,
        bench,
        demo,
        reference,
    } = GaitRun::load(&dir, stem)?;
    let rig = Rig::new(&model).ok_or("the character has no gait rig")?;
    let env_config = config.env.clone();
    let setup = EvalSetup {
        model: &model,
        catalogue: &bench.catalogue,
        sim: &config.sim,
        env: &env_config,
        batch: 1,
        language: false,
        gait: Some(GaitStart {
            demo: &demo,
            reference: Arc::clone(&reference),
            rest: true,
        }),
        max_steps: Some(300),
        action_std: 0.0,
    };
    println!(
        "task,seed,distance,step,end,fell,phase,v_fwd,v_lat,ref_v_fwd,ref_v_lat,d_fwd,d_lat,\
         ref_d_fwd,ref_d_lat,pitch_err,roll_err,rate_pitch,rate_roll,stance_mismatch,root_z,to_object,\
         to_other,others_moved,slip_fwd_0,slip_lat_0,slip_fwd_1,slip_lat_1,hip_y_0,hip_y_1,ref_hip_y_0,ref_hip_y_1,\
         knee_0,knee_1,ref_knee_0,ref_knee_1,ankle_y_0,ankle_y_1,ref_ankle_y_0,ref_ankle_y_1"
    );
    // The first pair alone, as `lhm eval --first-pair` plays it (the other objects stay).
    let first_pairs: Vec<_> = bench
        .tasks(Split::Unseen)
        .iter()
        .filter_map(|t| t.single_pair(0))
        .collect();
    for task in &first_pairs {
        for seed in 0..seeds {
            let mut env = setup.env_for(task, seed);
            let distance = env.first_object_distance();
            if distance < min_distance {
                break;
            }
            let first = task
                .sequence
                .first()
                .and_then(|p| task.object_index(&p.object));
            // Horizontal distances (m) from the root to the first object's centre and to the
            // nearest other movable object's.
            let distances = |root: &lhm_sim::obs::BodyState| {
                let mut to_first = f32::NAN;
                let mut to_other = f32::INFINITY;
                for (i, o) in task.objects.iter().enumerate() {
                    let d = (o.pos[0] as f32 - root.pos.x).hypot(o.pos[1] as f32 - root.pos.y);
                    if Some(i) == first {
                        to_first = d;
                    } else {
                        to_other = to_other.min(d);
                    }
                }
                (to_first, to_other)
            };
            // How far (m) the other movable objects have been pushed since the start: the
            // character walking into one.
            let at_start: Vec<_> = (0..task.objects.len())
                .map(|i| env.world.object_pose(i).map(|p| p.translation))
                .collect();
            let pushed = |env: &lhm_sim::env::TaskEnv| {
                at_start
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| Some(*i) != first)
                    .filter_map(|(i, p0)| {
                        Some((env.world.object_pose(i)?.translation - (*p0)?).length())
                    })
                    .fold(0.0f32, f32::max)
            };
            let mut rows = Vec::new();
            let (end, fell) = loop {
                let a = learner.actor_critic.act_deterministic(&env.observation())?;
                let r = env.step(&a);
                if let (Some(phase), false) = (env.gait_phase(), env.gait_stopped()) {
                    let now = env.world.body_states();
                    let k = (phase * reference.len() as f32).round() as usize;
                    let reference_now = aligned_to(reference.at(k).0, &now[0]);
                    let stance = rig.stance(&reference_now);
                    let (c, f) = (
                        balance(&rig, &now, stance),
                        balance(&rig, &reference_now, stance),
                    );
                    let tilt = rotation_error(c.pelvis, f.pelvis);
                    let (to_first, to_other) = distances(&now[0]);
                    // A foot on the ground that moves is slipping: its velocity forward (along
                    // the character's heading; < 0: sliding back) and sideways.
                    let heading = HeadingFrame::of(&now[0]);
                    let slip = rig.foot.map(|f| {
                        let b = &now[f];
                        if b.pos.z < CONTACT_HEIGHT {
                            let v = heading.vector(b.linvel);
                            format!("{:.3},{:.3}", v.x, v.y)
                        } else {
                            ",".to_string()
                        }
                    });
                    let (angles, reference_angles) =
                        (joint_angles(&model, &now), reference.at(k).1);
                    // Hip pitch, knee and ankle pitch, each leg's and the reference's.
                    let legs = [rig.hip_y, rig.knee, rig.ankle_y]
                        .iter()
                        .flat_map(|dofs| {
                            let (a, r) = (&angles, reference_angles);
                            [a[dofs[0]], a[dofs[1]], r[dofs[0]], r[dofs[1]]]
                        })
                        .map(|x| format!("{x:.3}"))
                        .collect::<Vec<_>>()
                        .join(",");
                    rows.push((env.steps(), format!(
                        "{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{:.3},{:.2},{:.2},{:.3},{},{},{}",
                        phase,
                        c.v.x,
                        c.v.y,
                        f.v.x,
                        f.v.y,
                        c.d.x,
                        c.d.y,
                        f.d.x,
                        f.d.y,
                        tilt.y,
                        tilt.x,
                        c.rate.y - f.rate.y,
                        c.rate.x - f.rate.x,
                        u8::from(rig.stance(&now) != stance),
                        now[0].pos.z,
                        to_first,
                        to_other,
                        pushed(&env),
                        slip[0],
                        slip[1],
                        legs
                    )));
                }
                if r.done || r.truncated || r.physics_invalid {
                    break (env.steps(), r.fell);
                }
            };
            // `step`: the env's step count after the step the row describes (as `end` counts).
            for (step, row) in &rows {
                println!(
                    "{},{seed},{distance:.2},{step},{end},{},{row}",
                    task.id,
                    u8::from(fell)
                );
            }
        }
    }
    Ok(())
}
