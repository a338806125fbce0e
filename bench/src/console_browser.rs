//! A headless Chromium for the console's benchmark, driven over WebDriver
//! (its garbage collector exposed and its heap figures precise).

use std::io::BufRead;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// chromedriver and its Chromium session; both end when dropped.
pub struct Browser {
    driver: Child,
    pub client: fantoccini::Client,
    _profile: tempfile::TempDir,
}

impl Drop for Browser {
    fn drop(&mut self) {
        // chromedriver and the Chromium it started share a process group of
        // their own: all of it goes.
        if let Ok(pid) = i32::try_from(self.driver.id()) {
            let _ = rustix::process::kill_process_group(
                rustix::process::Pid::from_raw(pid).expect("a child's pid"),
                rustix::process::Signal::KILL,
            );
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

impl Browser {
    /// Starts `chromedriver` on a port the system picks and a session of
    /// `chromium` through it.
    pub async fn start(chromium: &Path, chromedriver: &Path) -> anyhow::Result<Browser> {
        let mut driver = Command::new(chromedriver)
            .arg("--port=0")
            .process_group(0)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| {
                anyhow::anyhow!(
                    "{}: {e} (apt-get install chromium chromium-driver)",
                    chromedriver.display()
                )
            })?;
        let stdout = driver
            .stdout
            .take()
            .ok_or_else(|| anyhow::anyhow!("no stdout"))?;
        let mut port = None;
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            if let Some(p) = line.strip_prefix("ChromeDriver was started successfully on port ") {
                port = p.trim_end_matches('.').parse::<u16>().ok();
                break;
            }
        }
        let port = port.ok_or_else(|| anyhow::anyhow!("chromedriver did not say its port"))?;
        let profile = tempfile::tempdir()?;
        let mut caps = serde_json::Map::new();
        caps.insert(
            "goog:chromeOptions".into(),
            serde_json::json!({
                "binary": chromium,
                "args": [
                    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                    "--no-first-run", "--disable-background-networking",
                    "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
                    "--window-size=1280,900", "--enable-precise-memory-info",
                    "--js-flags=--expose-gc",
                    format!("--user-data-dir={}", profile.path().display()),
                ],
            }),
        );
        let client = fantoccini::ClientBuilder::new(
            hyper_util::client::legacy::connect::HttpConnector::new(),
        )
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{port}"))
        .await?;
        Ok(Browser {
            driver,
            client,
            _profile: profile,
        })
    }

    /// Waits (up to 5 minutes) until `script` returns true.
    pub async fn until(&self, script: &str) -> anyhow::Result<()> {
        let deadline = Instant::now() + Duration::from_secs(300);
        while self.client.execute(script, vec![]).await? != serde_json::Value::Bool(true) {
            anyhow::ensure!(Instant::now() < deadline, "never: {script}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Ok(())
    }
}
