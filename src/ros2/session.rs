//! Opening the Zenoh session, from the one place every process of polymap (and its tests and
//! examples) gets its config:
//!
//! 1. `zenoh.config_file` when the config names one;
//! 2. else `ZENOH_SESSION_CONFIG_URI` (rmw_zenoh's variable) or `ZENOH_CONFIG` (Zenoh's);
//! 3. else rmw_zenoh's own session defaults: a peer that connects to the rmw_zenohd router on
//!    this machine (tcp/localhost:7447), listens on loopback only, multicast scouting off,
//!    gossip on, timestamps on.
//!
//! `ZENOH_CONFIG_OVERRIDE` (`key=json5;key=json5`, as rmw_zenoh reads it) then changes
//! single keys of whichever it was.

use std::path::Path;

use super::Ros2Error;

/// rmw_zenoh's variable naming the session config file.
pub const SESSION_CONFIG_URI: &str = "ZENOH_SESSION_CONFIG_URI";
/// Zenoh's variable naming a config file.
pub const ZENOH_CONFIG: &str = "ZENOH_CONFIG";
/// rmw_zenoh's per-key overrides.
pub const CONFIG_OVERRIDE: &str = "ZENOH_CONFIG_OVERRIDE";

/// The rmw_zenohd router's endpoint on this machine.
pub const ROUTER_ON_THIS_MACHINE: &str = "tcp/localhost:7447";

/// The session config: from `file` (if not empty), else from the environment, else
/// rmw_zenoh's defaults; then the environment's overrides.
pub fn config(file: &Path) -> Result<zenoh::Config, Ros2Error> {
    let from_env =
        [SESSION_CONFIG_URI, ZENOH_CONFIG].iter().find_map(|v| std::env::var(v).ok().filter(|s| !s.is_empty()));
    let mut config = if !file.as_os_str().is_empty() {
        from_file(file)?
    } else if let Some(path) = from_env {
        from_file(Path::new(&path))?
    } else {
        rmw_zenoh_defaults()
    };
    if let Ok(overrides) = std::env::var(CONFIG_OVERRIDE) {
        for pair in overrides.split(';').map(str::trim).filter(|p| !p.is_empty()) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(Ros2Error::zenoh(CONFIG_OVERRIDE, format!("{pair:?} is not key=value")));
            };
            config
                .insert_json5(key.trim(), value.trim())
                .map_err(|e| Ros2Error::zenoh(format!("{CONFIG_OVERRIDE}: {key}"), e))?;
        }
    }
    Ok(config)
}

fn from_file(path: &Path) -> Result<zenoh::Config, Ros2Error> {
    // Zenoh reads the whole file: refuse what cannot be a config (/dev/zero, a huge file).
    const MAX_BYTES: u64 = 1 << 20;
    let meta = std::fs::metadata(path).map_err(|e| Ros2Error::zenoh(format!("zenoh config {}", path.display()), e))?;
    if !meta.is_file() || meta.len() > MAX_BYTES {
        return Err(Ros2Error::zenoh(
            format!("zenoh config {}", path.display()),
            format!("not a regular file of at most {MAX_BYTES} bytes"),
        ));
    }
    zenoh::Config::from_file(path).map_err(|e| Ros2Error::zenoh(format!("zenoh config {}", path.display()), e))
}

fn parse(json: serde_json::Value) -> zenoh::Config {
    zenoh::Config::from_json5(&json.to_string()).expect("Zenoh's own keys")
}

/// rmw_zenoh's `DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5`: the keys that differ from Zenoh's.
pub fn rmw_zenoh_defaults() -> zenoh::Config {
    parse(serde_json::json!({
        "mode": "peer",
        "connect": { "endpoints": [ROUTER_ON_THIS_MACHINE] },
        "listen": { "endpoints": ["tcp/localhost:0"] },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": true } },
        "timestamping": { "enabled": true },
    }))
}

/// A peer listening on loopback only (port `listen`, any if None), multicast off, connecting
/// to `connect` (endpoints such as `tcp/127.0.0.1:7447`): as the text of a JSON5 config file.
pub fn peer_json5(listen: Option<u16>, connect: &[String]) -> String {
    serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": [format!("tcp/127.0.0.1:{}", listen.unwrap_or(0))] },
        "connect": { "endpoints": connect },
        "scouting": { "multicast": { "enabled": false } },
        "timestamping": { "enabled": true },
    })
    .to_string()
}

/// A peer on loopback only, listening on port `listen` and connecting to the peers on the
/// loopback ports `connect`: for a process started with a config file (the tests, `polymap
/// demo`).
pub fn loopback_json5(listen: Option<u16>, connect: &[u16]) -> String {
    peer_json5(listen, &connect.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect::<Vec<_>>())
}

/// A peer on loopback only that connects to `endpoint` (a client program's session).
pub fn connecting_to(endpoint: &str) -> Result<zenoh::Config, Ros2Error> {
    zenoh::Config::from_json5(&peer_json5(None, &[endpoint.to_string()])).map_err(|e| Ros2Error::zenoh(endpoint, e))
}

/// The same as a config.
pub fn loopback(listen: Option<u16>, connect: &[u16]) -> zenoh::Config {
    zenoh::Config::from_json5(&loopback_json5(listen, connect)).expect("Zenoh's own keys")
}

/// Opens a session with `config`. A client whose config says to wait for its router
/// (`connect.timeout_ms = -1`) waits here: the log says for what.
pub async fn open(config: zenoh::Config) -> Result<zenoh::Session, Ros2Error> {
    let key = |k: &str| config.get_json(k).unwrap_or_default();
    tracing::info!(
        "Zenoh: opening a {} session, connecting to {}",
        key("mode").trim_matches('"'),
        key("connect/endpoints")
    );
    let session = zenoh::open(config).await.map_err(|e| Ros2Error::zenoh("opening the session", e))?;
    tracing::info!("Zenoh: session {} open", session.zid());
    Ok(session)
}

/// A TCP port on 127.0.0.1 that nothing listens on now.
pub fn free_loopback_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}
