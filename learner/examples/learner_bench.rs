//! Prints the learner step benchmark as JSON. Run in release mode, e.g.
//! `RAYON_NUM_THREADS=2 cargo run --release -j 1 -p lhm-learner --example learner_bench`.

fn main() -> Result<(), lhm_learner::LearnerError> {
    let result = lhm_learner::bench::run(&lhm_learner::bench::BenchSpec::default())?;
    println!(
        "{}",
        serde_json::to_string_pretty(&result).unwrap_or_default()
    );
    Ok(())
}
