//! The CLI's end of the live protocol: addresses, rooms, sockets.

use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};
use egoexo_protocol::live::{ClientMessage, CloseKind, Join, LIVE_SUBPROTOCOL, LiveLink, RelayMessage, RoomCreated};
use egoexo_protocol::share::ApiError;
use futures::{SinkExt, StreamExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

pub type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// A server given as `http(s)://host[/…]` or `ws(s)://host/live`: its page's base address
/// (`http://host`) and its relay (`ws://host/live`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ServerAddress {
    pub http: String,
    pub live: String,
}

impl ServerAddress {
    pub fn parse(text: &str) -> Result<ServerAddress> {
        let (scheme, rest) =
            text.split_once("://").with_context(|| format!("`{text}`: expected http(s):// or ws(s)://"))?;
        let host = rest.split(['/', '#', '?']).next().unwrap_or_default();
        if host.is_empty() {
            bail!("`{text}`: no host");
        }
        let secure = match scheme {
            "http" | "ws" => false,
            "https" | "wss" => true,
            other => bail!("`{text}`: the scheme `{other}` is neither http(s) nor ws(s)"),
        };
        let (http, ws) = if secure { ("https", "wss") } else { ("http", "ws") };
        Ok(ServerAddress { http: format!("{http}://{host}"), live: format!("{ws}://{host}/live") })
    }

    /// The page address that watches `link`'s room.
    pub fn watch_link(&self, link: &LiveLink) -> String {
        format!("{}/#{}", self.http, link.fragment())
    }

    /// The headset page address that joins `link`'s room as a device.
    pub fn device_link(&self, link: &LiveLink) -> String {
        format!("{}/xr.html#{}", self.http, link.fragment())
    }

    /// The camera page address that joins `link`'s room as a static observer.
    pub fn camera_link(&self, link: &LiveLink) -> String {
        format!("{}/observe.html#{}", self.http, link.fragment())
    }
}

/// How a command names a room: a device code (`7KQ-M4T`) or a link (`https://host/#live=…`,
/// or bare `<room>.<secret>`); [`Join::parse`].
pub fn parse_join(text: &str) -> Result<Join> {
    Join::parse(text).with_context(|| format!("--room `{text}`"))
}

/// `POST /api/live/rooms`.
pub fn create_room(server: &ServerAddress) -> Result<RoomCreated> {
    let url = format!("{}/api/live/rooms", server.http);
    let agent: ureq::Agent = ureq::Agent::config_builder().http_status_as_error(false).build().into();
    let mut response = agent.post(&url).send_empty().with_context(|| format!("cannot reach {url}"))?;
    let status = response.status().as_u16();
    let body = response.body_mut().read_to_vec().with_context(|| format!("reading the answer of {url}"))?;
    if status != 201 {
        let message = serde_json::from_slice::<ApiError>(&body)
            .map(|e| e.error.message)
            .unwrap_or_else(|_| String::from_utf8_lossy(&body).chars().take(200).collect());
        bail!("{url} answered {status}: {message}");
    }
    serde_json::from_slice(&body).with_context(|| format!("{url} did not answer with a room"))
}

/// Opens the relay's socket with the protocol's subprotocol.
pub async fn connect(server: &ServerAddress) -> Result<Socket> {
    let mut request = server.live.as_str().into_client_request().with_context(|| format!("`{}`", server.live))?;
    request.headers_mut().insert("Sec-WebSocket-Protocol", HeaderValue::from_static(LIVE_SUBPROTOCOL));
    let (socket, _) = tokio_tungstenite::connect_async(request)
        .await
        .with_context(|| format!("cannot connect to {}", server.live))?;
    Ok(socket)
}

pub fn json(message: &ClientMessage) -> Message {
    Message::Text(serde_json::to_string(message).unwrap_or_default().into())
}

/// A close from the relay, in words.
pub fn describe_close(frame: Option<&CloseFrame>) -> String {
    match frame {
        Some(frame) => {
            let code = u16::from(frame.code);
            let kind = CloseKind::from_code(code).map(|k| format!(" ({k:?})")).unwrap_or_default();
            format!("the relay closed the connection: {code}{kind}: {}", frame.reason)
        }
        None => "the relay closed the connection".to_string(),
    }
}

/// Sends the hello and waits for the welcome (answering pings meanwhile with `clock_ns`).
pub async fn hello(socket: &mut Socket, hello: &ClientMessage, clock_ns: impl Fn() -> i64) -> Result<RelayMessage> {
    socket.send(json(hello)).await.context("sending hello")?;
    loop {
        let message = tokio::time::timeout(std::time::Duration::from_secs(10), socket.next())
            .await
            .context("no welcome from the relay within 10 s")?;
        match message {
            Some(Ok(Message::Text(text))) => {
                let message: RelayMessage = serde_json::from_str(&text).context("the relay's message")?;
                match message {
                    RelayMessage::Welcome { .. } => return Ok(message),
                    RelayMessage::Ping { relay_ns } => {
                        socket.send(json(&ClientMessage::Pong { relay_ns, device_ns: clock_ns() })).await?;
                    }
                    _ => {}
                }
            }
            Some(Ok(Message::Close(frame))) => bail!("{}", describe_close(frame.as_ref())),
            Some(Ok(_)) => {}
            Some(Err(e)) => bail!("the relay's socket: {e}"),
            None => bail!("the relay closed the connection before welcoming"),
        }
    }
}

/// A device waiting to send its next frame: answers the relay's clock pings with `clock_ns`
/// until `at`; an error if the relay closes the connection meanwhile (`device` names it).
pub async fn answer_pings_until(
    socket: &mut Socket,
    at: tokio::time::Instant,
    clock_ns: impl Fn() -> i64,
    device: &str,
) -> Result<()> {
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(at) => return Ok(()),
            message = socket.next() => match message {
                Some(Ok(Message::Text(text))) => {
                    if let Ok(RelayMessage::Ping { relay_ns }) = serde_json::from_str(&text) {
                        socket.send(json(&ClientMessage::Pong { relay_ns, device_ns: clock_ns() })).await?;
                    }
                }
                Some(Ok(Message::Close(frame))) => bail!("device `{device}`: {}", describe_close(frame.as_ref())),
                Some(Ok(_)) => {}
                Some(Err(e)) => bail!("device `{device}`: {e}"),
                None => bail!("device `{device}`: the relay closed the connection"),
            },
        }
    }
}

/// The system clock, nanoseconds since the Unix epoch.
pub fn system_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn server_addresses_and_room_names() {
        let s = ServerAddress::parse("http://127.0.0.1:8080/").unwrap();
        assert_eq!((s.http.as_str(), s.live.as_str()), ("http://127.0.0.1:8080", "ws://127.0.0.1:8080/live"));
        let s = ServerAddress::parse("wss://egoexo.example.org/live").unwrap();
        assert_eq!(s.http, "https://egoexo.example.org");
        assert!(ServerAddress::parse("ftp://x").is_err() && ServerAddress::parse("x").is_err());
        let link = LiveLink { room: "r00m".into(), secret: "s3c".into() };
        assert_eq!(s.device_link(&link), "https://egoexo.example.org/xr.html#live=r00m.s3c");
        assert!(matches!(parse_join("7kq-m4t").unwrap(), Join::Code { .. }));
        assert!(matches!(parse_join("http://h/#live=r00m.s3c").unwrap(), Join::Secret { .. }));
        assert!(parse_join("nonsense!").is_err());
    }
}
