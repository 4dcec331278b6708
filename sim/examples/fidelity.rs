//! `cargo run --release -p lhm-sim --example fidelity -- [SERVO] [ITERS] [PIPELINE] [PHYSICS_HZ]`:
//! the fidelity scenarios at one setting, as JSON (the `lhm bench fidelity` sweep's building block).
use lhm_sim::character::ServoModel;
use lhm_sim::fidelity::run_fidelity;
use lhm_sim::{CharacterModel, SimConfig};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let servo = match args.first().map(String::as_str) {
        Some("motor") => ServoModel::MotorConstraint,
        _ => ServoModel::ImplicitSpring,
    };
    let num = |i: usize, d: f32| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let sim = SimConfig {
        servo,
        solver_iterations: num(1, 1.0) as usize,
        pipeline_steps_per_control: num(2, 2.0) as usize,
        physics_hz: num(3, 120.0),
        ..SimConfig::default()
    };
    let r = run_fidelity(&CharacterModel::amp_humanoid(), &sim);
    println!("{}", serde_json::to_string_pretty(&r).unwrap_or_default());
}
