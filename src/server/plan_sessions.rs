//! The plans the `plan` route keeps between control steps, one per session,
//! so each call warm-starts from the last: at most `capacity` sessions (the
//! least recently used goes when a new one needs room), each forgotten
//! `ttl` after its last use. An unknown or expired session is an error
//! naming it, never a silent cold start.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::ApiError;

/// What a session keeps of its last call.
#[derive(Debug, Clone, PartialEq)]
pub struct KeptPlan {
    /// `[horizon, act_dim]`, row-major.
    pub actions: Vec<f32>,
    /// iCEM's last elites, `[k, horizon, act_dim]` (empty for the other planners).
    pub elites: Vec<f32>,
}

/// One session's last plan and what it was planned for.
#[derive(Debug, Clone)]
struct Session {
    model: String,
    horizon: usize,
    plan: KeptPlan,
    used: Instant,
}

/// The sessions of every model, bounded in count and age.
#[derive(Debug)]
pub struct PlanSessions {
    sessions: Mutex<HashMap<String, Session>>,
    capacity: usize,
    ttl: Duration,
}

impl PlanSessions {
    pub fn new(capacity: usize, ttl: Duration) -> Self {
        Self {
            sessions: Mutex::new(HashMap::new()),
            capacity: capacity.max(1),
            ttl,
        }
    }

    /// A fresh session id (unguessable, so one client cannot steer another's plan).
    pub fn new_id() -> String {
        format!("{:032x}", rand::random::<u128>())
    }

    /// The last plan of session `id`, checked to be `model`'s at `horizon`;
    /// `now` is when the request arrived.
    pub fn warm(
        &self,
        id: &str,
        model: &str,
        horizon: usize,
        now: Instant,
    ) -> Result<KeptPlan, ApiError> {
        let mut sessions = self.lock();
        let Some(session) = sessions.get(id) else {
            return Err(ApiError::UnknownSession(format!(
                "session `{id}` is unknown (open one with \"open_session\": true)"
            )));
        };
        if now.saturating_duration_since(session.used) >= self.ttl {
            sessions.remove(id);
            return Err(ApiError::UnknownSession(format!(
                "session `{id}` expired: unused for {} s or more",
                self.ttl.as_secs()
            )));
        }
        if session.model != model || session.horizon != horizon {
            return Err(ApiError::Invalid(format!(
                "session `{id}` plans for model `{}` at horizon {}, not `{model}` at {horizon}",
                session.model, session.horizon
            )));
        }
        Ok(session.plan.clone())
    }

    /// Keeps `plan` as session `id`'s last, used at `now`.
    pub fn keep(&self, id: &str, model: &str, horizon: usize, plan: KeptPlan, now: Instant) {
        let mut sessions = self.lock();
        let session = Session {
            model: model.to_string(),
            horizon,
            plan,
            used: now,
        };
        if !sessions.contains_key(id) && sessions.len() >= self.capacity {
            let oldest = (sessions.iter())
                .min_by_key(|(_, s)| s.used)
                .map(|(k, _)| k.clone());
            if let Some(oldest) = oldest {
                sessions.remove(&oldest);
            }
        }
        sessions.insert(id.to_string(), session);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Session>> {
        // A panic while holding the lock leaves only whole entries behind.
        self.sessions.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kept(actions: &[f32]) -> KeptPlan {
        KeptPlan {
            actions: actions.to_vec(),
            elites: vec![-1.0; 2 * actions.len()],
        }
    }

    #[test]
    fn a_session_keeps_its_plan_until_it_expires() {
        let sessions = PlanSessions::new(4, Duration::from_secs(10));
        let t0 = Instant::now();
        sessions.keep("a", "hopper", 2, kept(&[1.0, 2.0]), t0);
        let later = t0 + Duration::from_secs(9);
        assert_eq!(
            sessions.warm("a", "hopper", 2, later).unwrap(),
            kept(&[1.0, 2.0])
        );
        let error = sessions.warm("a", "walker", 2, later).unwrap_err();
        assert!(error.to_string().contains("not `walker` at 2"), "{error}");
        let expired = sessions.warm("a", "hopper", 2, t0 + Duration::from_secs(10));
        assert!(expired.unwrap_err().to_string().contains("expired"));
        let gone = sessions.warm("a", "hopper", 2, t0).unwrap_err();
        assert!(gone.to_string().contains("unknown"), "{gone}");
    }

    #[test]
    fn the_least_recently_used_session_makes_room() {
        let sessions = PlanSessions::new(2, Duration::from_secs(10));
        let t0 = Instant::now();
        let at = |s| t0 + Duration::from_secs(s);
        sessions.keep("a", "m", 1, kept(&[1.0]), at(0));
        sessions.keep("b", "m", 1, kept(&[2.0]), at(1));
        sessions.keep("a", "m", 1, kept(&[3.0]), at(2));
        sessions.keep("c", "m", 1, kept(&[4.0]), at(3));
        assert!(
            sessions.warm("b", "m", 1, at(3)).is_err(),
            "b was the oldest"
        );
        assert_eq!(sessions.warm("a", "m", 1, at(3)).unwrap(), kept(&[3.0]));
        assert_eq!(sessions.warm("c", "m", 1, at(3)).unwrap(), kept(&[4.0]));
    }
}
