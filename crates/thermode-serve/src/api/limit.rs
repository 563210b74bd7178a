//! A token bucket: the per-connection (WebSocket) and per-daemon (OSC) request rate limit. Time comes in as an
//! argument, so the bucket is deterministic under test.

/// A token bucket refilled at `rate_per_s` up to `burst` tokens.
#[derive(Debug, Clone, PartialEq)]
pub struct TokenBucket {
    rate_per_s: f64,
    burst: f64,
    tokens: f64,
    last_s: Option<f64>,
}

impl TokenBucket {
    /// A full bucket: `rate_per_s` \[1/s\] sustained, `burst` requests at once.
    pub fn new(rate_per_s: f64, burst: f64) -> Self {
        TokenBucket {
            rate_per_s,
            burst,
            tokens: burst,
            last_s: None,
        }
    }

    /// Takes one token at time `now_s` \[s\]; false when the bucket is empty (the request is refused).
    pub fn take(&mut self, now_s: f64) -> bool {
        self.take_many(1.0, now_s)
    }

    /// Takes `n` tokens at once at time `now_s` \[s\] (the OSC subscribers' byte budget: one token a byte); false,
    /// taking nothing, when fewer are left.
    pub fn take_many(&mut self, n: f64, now_s: f64) -> bool {
        if let Some(last) = self.last_s {
            let elapsed = (now_s - last).max(0.0);
            self.tokens = (self.tokens + elapsed * self.rate_per_s).min(self.burst);
        }
        self.last_s = Some(self.last_s.map_or(now_s, |l| l.max(now_s)));
        if self.tokens >= n {
            self.tokens -= n;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn burst_then_sustained_rate() {
        let mut bucket = TokenBucket::new(50.0, 100.0);
        let granted = (0..150).filter(|_| bucket.take(0.0)).count();
        assert_eq!(granted, 100, "burst");
        // one second later: 50 more
        let granted = (0..150).filter(|_| bucket.take(1.0)).count();
        assert_eq!(granted, 50, "refill over 1 s");
        assert!(!bucket.take(0.5), "time going back grants nothing");
    }

    #[test]
    fn many_tokens_are_taken_whole_or_not_at_all() {
        let mut bytes = TokenBucket::new(1000.0, 500.0);
        assert!(bytes.take_many(400.0, 0.0));
        assert!(!bytes.take_many(200.0, 0.0), "100 left: 200 refused, none taken");
        assert!(bytes.take_many(100.0, 0.0));
        assert!(bytes.take_many(300.0, 0.3), "300 refilled in 0.3 s");
    }
}
