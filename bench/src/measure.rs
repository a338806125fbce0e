//! What the benchmark reads off the processes under test: CPU time and
//! memory from `/proc`, and the agent's Prometheus metrics over HTTP.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

use anyhow::{anyhow, Context};

/// Linux reports CPU times in clock ticks of 1/100 s (`USER_HZ`, fixed by
/// the kernel's ABI).
const TICKS_PER_SECOND: f64 = 100.0;

/// CPU seconds (user + system, all threads) a process has used.
pub fn cpu_seconds(pid: u32) -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .with_context(|| format!("process {pid} is gone"))?;
    // The command name (field 2) may hold spaces: count after its ')'.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .ok_or_else(|| anyhow!("unreadable /proc/{pid}/stat"))?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| -> anyhow::Result<f64> {
        Ok(fields
            .get(i)
            .ok_or_else(|| anyhow!("short /proc/{pid}/stat"))?
            .parse::<f64>()?)
    };
    // utime and stime are fields 14 and 15; field 3 is rest's first.
    Ok((tick(11)? + tick(12)?) / TICKS_PER_SECOND)
}

/// The process's resident memory now and at its peak, in bytes.
pub fn rss(pid: u32) -> anyhow::Result<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .with_context(|| format!("process {pid} is gone"))?;
    let kb = |key: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
            * 1024
    };
    Ok((kb("VmRSS:"), kb("VmHWM:")))
}

/// One scrape of a Prometheus text endpoint.
pub struct Scrape(String);

impl Scrape {
    /// `GET /metrics` from `addr`.
    pub fn get(addr: SocketAddr) -> anyhow::Result<Scrape> {
        let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(5))
            .with_context(|| format!("cannot reach the agent's metrics at {addr}"))?;
        s.set_read_timeout(Some(Duration::from_secs(10)))?;
        write!(
            s,
            "GET /metrics HTTP/1.0\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
        )?;
        let mut body = String::new();
        s.read_to_string(&mut body)?;
        Ok(Scrape(body))
    }

    /// The value of the series `name` (whatever its labels), summed over
    /// every series of that name.
    pub fn value(&self, name: &str) -> f64 {
        self.0
            .lines()
            .filter(|l| !l.starts_with('#'))
            .filter_map(|l| {
                let (series, value) = l.rsplit_once(' ')?;
                let base = series.split('{').next()?;
                (base == name).then(|| value.parse::<f64>().ok())?
            })
            .sum()
    }

    /// The histogram `name`'s buckets: (upper bound, cumulative count).
    pub fn buckets(&self, name: &str) -> Vec<(f64, f64)> {
        let prefix = format!("{name}_bucket{{");
        let mut out: Vec<(f64, f64)> = self
            .0
            .lines()
            .filter_map(|l| {
                let rest = l.strip_prefix(&prefix)?;
                let le = rest.split("le=\"").nth(1)?.split('"').next()?;
                let le = if le == "+Inf" {
                    f64::INFINITY
                } else {
                    le.parse().ok()?
                };
                let count = l.rsplit_once(' ')?.1.parse().ok()?;
                Some((le, count))
            })
            .collect();
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        out
    }
}

/// The upper bound of the bucket holding quantile `q` of the difference
/// between two scrapes of a histogram: "p99 ≤ this".
#[cfg(test)]
pub fn bucket_quantile(before: &[(f64, f64)], after: &[(f64, f64)], q: f64) -> Option<f64> {
    counts_quantile(&bucket_counts(before, after), q)
}

/// The upper bound of the bucket holding quantile `q` of cumulative
/// bucket `counts` (from [`bucket_counts`]).
pub fn counts_quantile(counts: &[(f64, f64)], q: f64) -> Option<f64> {
    let total = counts.last()?.1;
    if total <= 0.0 {
        return None;
    }
    counts
        .iter()
        .find(|&&(_, n)| n >= q * total)
        .map(|&(le, _)| le)
}

/// The cumulative counts of a histogram between two scrapes: (upper
/// bound, observations ≤ it).
pub fn bucket_counts(before: &[(f64, f64)], after: &[(f64, f64)]) -> Vec<(f64, f64)> {
    after
        .iter()
        .map(|&(le, n)| {
            let was = before
                .iter()
                .find(|b| b.0 == le)
                .map(|b| b.1)
                .unwrap_or(0.0);
            (le, n - was)
        })
        .collect()
}

/// Quantile `q` of `samples` (nearest rank), or `None` when empty.
pub fn quantile(samples: &[f64], q: f64) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let mut s = samples.to_vec();
    s.sort_by(f64::total_cmp);
    let rank = ((q * s.len() as f64).ceil() as usize).clamp(1, s.len());
    Some(s[rank - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_by_nearest_rank_and_by_bucket() {
        let s: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&s, 0.5), Some(50.0));
        assert_eq!(quantile(&s, 0.99), Some(99.0));
        assert_eq!(quantile(&[], 0.5), None);
        let before = [(0.001, 10.0), (0.01, 10.0), (f64::INFINITY, 10.0)];
        let after = [(0.001, 100.0), (0.01, 109.0), (f64::INFINITY, 110.0)];
        // 100 new: 90 at ≤ 1 ms, 9 more at ≤ 10 ms, one beyond.
        assert_eq!(bucket_quantile(&before, &after, 0.5), Some(0.001));
        assert_eq!(bucket_quantile(&before, &after, 0.99), Some(0.01));
        assert_eq!(bucket_quantile(&before, &after, 1.0), Some(f64::INFINITY));
    }

    #[test]
    fn scrape_sums_series_and_reads_buckets() {
        let s = Scrape(
            "# HELP x\nx_total{cell=\"a\"} 3\nx_total{cell=\"b\"} 4\nx_totally 9\n\
             h_bucket{cell=\"a\",le=\"0.5\"} 2\nh_bucket{cell=\"a\",le=\"+Inf\"} 5\n"
                .into(),
        );
        assert_eq!(s.value("x_total"), 7.0);
        assert_eq!(s.buckets("h"), vec![(0.5, 2.0), (f64::INFINITY, 5.0)]);
    }

    #[test]
    fn own_process_is_measured() {
        let pid = std::process::id();
        let (now, peak) = rss(pid).unwrap();
        assert!(now > 0 && peak >= now);
        assert!(cpu_seconds(pid).unwrap() >= 0.0);
    }
}
