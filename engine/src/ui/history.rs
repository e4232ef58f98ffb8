//! The overlay's frame-time history: a fixed ring of the last N samples (no allocation per
//! frame), with the median and p99 the graph prints. Order matters only for the graph, so the
//! ring keeps a write cursor and hands out samples oldest first.

use crate::stats::percentile;

/// How many frames the graph shows.
pub const HISTORY_FRAMES: usize = 240;

/// The last `capacity` samples of one series, in milliseconds.
#[derive(Debug, Clone)]
pub struct Ring {
    samples: Vec<f64>,
    capacity: usize,
    /// Where the next sample goes once the ring is full.
    next: usize,
}

impl Ring {
    pub fn new(capacity: usize) -> Ring {
        assert!(capacity > 0, "a ring holds at least one sample");
        Ring {
            samples: Vec::with_capacity(capacity),
            capacity,
            next: 0,
        }
    }

    pub fn push(&mut self, ms: f64) {
        if self.samples.len() < self.capacity {
            self.samples.push(ms);
        } else {
            self.samples[self.next] = ms;
        }
        self.next = (self.next + 1) % self.capacity;
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Samples oldest first.
    pub fn iter(&self) -> impl Iterator<Item = f64> + '_ {
        let split = if self.samples.len() < self.capacity { 0 } else { self.next };
        self.samples[split..].iter().chain(&self.samples[..split]).copied()
    }

    pub fn last(&self) -> Option<f64> {
        if self.samples.is_empty() {
            return None;
        }
        Some(self.samples[(self.next + self.capacity - 1) % self.capacity])
    }

    /// Nearest-rank percentile (`stats::percentile`) of the samples held.
    pub fn percentile(&self, p: f64) -> Option<f64> {
        percentile(&self.samples, p)
    }

    pub fn median(&self) -> Option<f64> {
        self.percentile(50.0)
    }

    pub fn p99(&self) -> Option<f64> {
        self.percentile(99.0)
    }

    pub fn max(&self) -> Option<f64> {
        self.samples.iter().copied().reduce(f64::max)
    }
}

/// CPU frame time and GPU time of the last `HISTORY_FRAMES` frames.
#[derive(Debug, Clone)]
pub struct FrameHistory {
    pub cpu_ms: Ring,
    pub gpu_ms: Ring,
}

impl Default for FrameHistory {
    fn default() -> Self {
        FrameHistory {
            cpu_ms: Ring::new(HISTORY_FRAMES),
            gpu_ms: Ring::new(HISTORY_FRAMES),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_keeps_the_last_samples_in_order() {
        let mut r = Ring::new(4);
        assert!(r.is_empty());
        assert_eq!((r.median(), r.p99(), r.last()), (None, None, None));
        for v in 1..=6 {
            r.push(v as f64);
        }
        assert_eq!(r.iter().collect::<Vec<_>>(), vec![3.0, 4.0, 5.0, 6.0]);
        assert_eq!((r.len(), r.last(), r.max()), (4, Some(6.0), Some(6.0)));
    }

    #[test]
    fn median_and_p99_cover_only_the_window() {
        let mut r = Ring::new(HISTORY_FRAMES);
        // Spikes that scroll out of the window must not count.
        for _ in 0..100 {
            r.push(1000.0);
        }
        // 1..=240 in a scrambled order (7 is coprime with 240, so this is a permutation).
        for i in 0..HISTORY_FRAMES {
            r.push(((i * 7) % HISTORY_FRAMES + 1) as f64);
        }
        assert_eq!(r.len(), HISTORY_FRAMES);
        // Nearest rank over 240 sorted samples: rank round(0.5 * 239) = 120 -> 121,
        // round(0.99 * 239) = 237 -> 238.
        assert_eq!(r.median(), Some(121.0));
        assert_eq!(r.p99(), Some(238.0));
        assert_eq!(r.max(), Some(240.0));
        // One spike among 240 moves p99 by one rank only; three of them reach it.
        r.push(5000.0);
        assert_eq!(r.p99(), Some(239.0));
        r.push(5000.0);
        r.push(5000.0);
        assert_eq!(r.p99(), Some(5000.0));
    }
}
