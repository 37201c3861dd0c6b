//! A run that failed for a cause outside its job (the spool full or failing, the store not
//! answering) puts the job back in the queue, after a backoff, a bounded number of times; only
//! the job's own faults (and a cancel) fail it.

use super::{Error, Job, Store, now_ms};
use std::time::Duration;

/// The longest pause before a job's next attempt, however many came before.
pub const MAX_BACKOFF: Duration = Duration::from_secs(300);

/// How long a job waits after its `attempts`-th run went wrong: `first`, doubled each attempt.
pub fn backoff(first: Duration, attempts: i64) -> Duration {
    let doublings = attempts.clamp(1, 20) as u32 - 1;
    first.saturating_mul(1 << doublings).min(MAX_BACKOFF)
}

impl Store {
    /// The run ended by `cause`, outside the job: its temporaries go (what it wrote is not the
    /// job's), and the job is queued again after `backoff(first, attempts)`, or, when it has
    /// run `max_attempts` times, failed with the cause. `true` when it is queued again.
    pub(in crate::jobs) async fn retry(&self, job: &Job, cause: &str, max_attempts: i64, first: Duration) -> Result<bool, Error> {
        if job.attempts >= max_attempts {
            let msg = format!("{cause} (attempt {} of {max_attempts}: not run again)", job.attempts);
            self.fail(job, &msg).await?;
            return Ok(false);
        }
        self.remove_outputs(job);
        let after = now_ms().saturating_add(backoff(first, job.attempts).as_millis() as i64);
        sqlx::query(
            "UPDATE jobs SET state = 'queued', started_ms = NULL, bytes_read = 0, blocks = 0, cause = $1, not_before_ms = $2
             WHERE id = $3 AND state = 'running' AND owner = $4",
        )
        .bind(cause)
        .bind(after)
        .bind(&job.id)
        .bind(&self.node)
        .execute(&self.pool)
        .await?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backoff_doubles_up_to_its_bound() {
        let s = Duration::from_secs(2);
        assert_eq!(backoff(s, 1), s);
        assert_eq!(backoff(s, 2), 2 * s);
        assert_eq!(backoff(s, 4), 8 * s);
        assert_eq!(backoff(s, 9), MAX_BACKOFF);
        assert_eq!(backoff(s, i64::MAX), MAX_BACKOFF);
        assert_eq!(backoff(s, 0), s);
    }
}
