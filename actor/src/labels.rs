//! Teacher labels for a student's rollout from the run's dagger-server (`lhm/<run>/dagger/label`):
//! one batched `LabelRequest` per control step of all the actor's environments.

use std::time::{Duration, Instant};

use lhm_cluster::shutdown;
use lhm_protos::{keys, LabelReply, LabelRequest, Stage, WireMessage};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::Wait;

use crate::rollout::Labeller;

/// How long one label query waits for a reply before it is asked again (short, so a stop
/// request is seen soon when the server has gone away without replying).
const QUERY_TIMEOUT: Duration = Duration::from_secs(2);
/// How often a student waiting for labels says why.
const WAITING_LINE_EVERY: Duration = Duration::from_secs(30);

/// Asks the dagger-server. A missing server, or one without teacher weights yet, is waited for
/// (a dagger-server may start after the actors, or restart); the actor's stop request ends the
/// wait with an error. Any other error reply (a refused request, a failed inference) or an
/// unreadable reply cannot get better by asking again and ends the rollout with it.
pub struct DaggerLabels<'s> {
    session: &'s zenoh::Session,
    key: String,
    run_id: String,
    next_request: u64,
    /// The student weights that visited the states (for the server's logs).
    pub student_version: u64,
}

impl<'s> DaggerLabels<'s> {
    pub fn new(session: &'s zenoh::Session, run_id: &str) -> Self {
        Self {
            session,
            key: keys::dagger_label(run_id),
            run_id: run_id.to_owned(),
            next_request: 1,
            student_version: 0,
        }
    }

    /// One query: `Ok(Ok(actions))`, or `Ok(Err(why))` when no usable reply came (worth asking
    /// again); `Err` for a reply that can never be right.
    fn ask(
        &self,
        request: &LabelRequest,
        bytes: &[u8],
    ) -> Result<Result<Vec<f32>, String>, String> {
        let replies = self
            .session
            .get(&self.key)
            .payload(bytes.to_vec())
            // The reply travels with the query's QoS: labels are never dropped.
            .congestion_control(CongestionControl::Block)
            .priority(Priority::DataHigh)
            .timeout(QUERY_TIMEOUT)
            .wait()
            .map_err(|e| format!("querying {}: {e}", self.key))?;
        let mut why = format!("no dagger-server answered on {}", self.key);
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else { continue };
            let reply = LabelReply::decode_checked(&sample.payload().to_bytes())
                .map_err(|e| format!("an unreadable label reply: {e}"))?;
            if reply.request_id != request.request_id {
                continue;
            }
            if !reply.error.is_empty() {
                if reply.error.starts_with(lhm_protos::LABEL_ERROR_NO_WEIGHTS) {
                    why = format!("the dagger-server says: {}", reply.error);
                    continue;
                }
                return Err(format!("the dagger-server says: {}", reply.error));
            }
            if reply.num_states != request.num_states {
                return Err(format!(
                    "the dagger-server labelled {} states of {}",
                    reply.num_states, request.num_states
                ));
            }
            return Ok(Ok(reply.actions));
        }
        Ok(Err(why))
    }
}

impl Labeller for DaggerLabels<'_> {
    fn label(&mut self, observations: &[f32], stages: &[Stage]) -> Result<Vec<f32>, String> {
        let n = stages.len();
        if n == 0 || observations.len() % n != 0 {
            return Err(format!(
                "{} observation values for {n} states",
                observations.len()
            ));
        }
        let request = LabelRequest {
            run_id: self.run_id.clone(),
            request_id: self.next_request,
            student_version: self.student_version,
            num_states: n as u32,
            obs_dim: (observations.len() / n) as u32,
            observations: observations.to_vec(),
            stages: stages.iter().map(|&s| s as i32).collect(),
            ..LabelRequest::versioned()
        };
        self.next_request += 1;
        let bytes = request.encode_checked().map_err(|e| e.to_string())?;
        let mut last_line: Option<Instant> = None;
        loop {
            match self.ask(&request, &bytes)? {
                Ok(actions) => return Ok(actions),
                Err(why) => {
                    if shutdown::requested() {
                        return Err(format!("stopped while waiting for labels ({why})"));
                    }
                    if last_line.is_none_or(|t| t.elapsed() >= WAITING_LINE_EVERY) {
                        tracing::warn!("waiting for teacher labels: {why}");
                        last_line = Some(Instant::now());
                    }
                    // An error reply comes back at once: do not hammer the server.
                    std::thread::sleep(Duration::from_millis(200));
                }
            }
        }
    }
}
