//! What a run log writes and serves ([`RunLogConfig`]), and its checks.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// What a run log writes and serves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunLogConfig {
    /// The MCAP file (written as `FILE.partial`, renamed when closed; a
    /// device or FIFO is written through when the run ends).
    pub mcap: Option<PathBuf>,
    /// Serve the Foxglove WebSocket protocol here (`host:port`).
    pub live: Option<String>,
    /// 3-D scenes per second of loop time.
    pub scene_hz: f64,
    /// Points along the backbone (and each tendon) in a scene.
    pub backbone_points: usize,
    /// Key–value pairs written as the MCAP's `run` metadata.
    pub metadata: BTreeMap<String, String>,
    /// Wait for the writer instead of dropping when it is behind: for runs
    /// faster than real time (`tendril dynamics`), never for a loop.
    pub lossless: bool,
}

impl Default for RunLogConfig {
    fn default() -> Self {
        RunLogConfig {
            mcap: None,
            live: None,
            scene_hz: 30.0,
            backbone_points: 41,
            metadata: BTreeMap::new(),
            lossless: false,
        }
    }
}

impl RunLogConfig {
    /// Whether anything is written or served.
    pub fn enabled(&self) -> bool {
        self.mcap.is_some() || self.live.is_some()
    }

    /// A clear error for values no run log can use.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.scene_hz.is_finite() && self.scene_hz > 0.0 && self.scene_hz <= 1000.0) {
            return Err(format!(
                "run log: scene rate {} Hz is not in (0, 1000]",
                self.scene_hz
            ));
        }
        if !(2..=1000).contains(&self.backbone_points) {
            return Err(format!(
                "run log: {} backbone points is not in 2..=1000",
                self.backbone_points
            ));
        }
        if let Some(addr) = &self.live {
            parse_addr(addr)?;
        }
        Ok(())
    }
}

/// `host:port` of a live view.
pub fn parse_addr(addr: &str) -> Result<(String, u16), String> {
    let (host, port) = addr
        .rsplit_once(':')
        .ok_or_else(|| format!("live address {addr:?}: expected HOST:PORT"))?;
    let port = port
        .parse::<u16>()
        .map_err(|e| format!("live address {addr:?}: port: {e}"))?;
    if host.is_empty() {
        return Err(format!("live address {addr:?}: no host"));
    }
    Ok((host.trim_matches(['[', ']']).to_string(), port))
}
