//! The share API between the page (or `egoexo share`) and the server, version
//! [`SHARE_API_VERSION`] (`docs/share-format.md`):
//!
//! | request | answer |
//! |---|---|
//! | `POST /api/shares?expires=1h\|1d\|30d` (body: the sealed share) | 201 [`CreatedShare`] |
//! | `GET /api/shares/{id}` | 200, the sealed bytes |
//! | `DELETE /api/shares/{id}` with `Authorization: Bearer <delete_token>` | 204 |
//! | `GET /api/config` | 200 [`ServerConfig`] |
//!
//! Errors are JSON [`ApiError`] with a machine-readable [`ApiErrorKind`]. The server stores
//! ciphertext only; the key is in the link's fragment and never reaches it: a link is
//! `<page>#share=<id>.<key>[&t=<time>]` ([`ShareLink`], [`LinkFragment`]).

use std::fmt;

use serde::{Deserialize, Serialize};

/// The API's version (in [`ServerConfig`]).
pub const SHARE_API_VERSION: u32 = 1;

/// Characters of a share id: 128 random bits, base64url without padding.
pub const SHARE_ID_LEN: usize = 22;

/// A share's id: 22 characters of `A–Z a–z 0–9 - _` (128 random bits, base64url). Anything
/// else is refused before it can reach storage.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct ShareId(String);

impl ShareId {
    /// Checks `text` is an id.
    pub fn parse(text: &str) -> Result<ShareId, String> {
        let ok = text.len() == SHARE_ID_LEN
            && text.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
            // The last of 22 characters carries the last 2 of the 128 bits, the rest zero.
            && text.bytes().last().is_some_and(|b| b"AQgw".contains(&b));
        if ok {
            Ok(ShareId(text.to_owned()))
        } else {
            Err(format!(
                "`{}` is not a share id (22 characters of A–Z, a–z, 0–9, `-`, `_`: 128 bits in base64url)",
                text.chars().take(40).collect::<String>()
            ))
        }
    }

    /// The id of 16 random bytes.
    pub fn from_bytes(bytes: [u8; 16]) -> ShareId {
        ShareId(base64url(&bytes))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl TryFrom<String> for ShareId {
    type Error = String;

    fn try_from(text: String) -> Result<Self, Self::Error> {
        ShareId::parse(&text)
    }
}

impl From<ShareId> for String {
    fn from(id: ShareId) -> Self {
        id.0
    }
}

impl fmt::Display for ShareId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// base64url without padding (RFC 4648 §5), as ids, keys and tokens are written.
pub fn base64url(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes)
}

/// Decodes base64url without padding.
pub fn from_base64url(text: &str) -> Option<Vec<u8>> {
    use base64::Engine as _;
    base64::engine::general_purpose::URL_SAFE_NO_PAD.decode(text).ok()
}

/// How long a share lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Expiry {
    #[serde(rename = "1h")]
    OneHour,
    #[serde(rename = "1d")]
    OneDay,
    #[serde(rename = "30d")]
    ThirtyDays,
}

impl Expiry {
    pub const ALL: [Expiry; 3] = [Expiry::OneHour, Expiry::OneDay, Expiry::ThirtyDays];

    /// `1h`, `1d` or `30d`.
    pub fn as_str(self) -> &'static str {
        match self {
            Expiry::OneHour => "1h",
            Expiry::OneDay => "1d",
            Expiry::ThirtyDays => "30d",
        }
    }

    /// The lifetime in seconds.
    pub fn seconds(self) -> u64 {
        match self {
            Expiry::OneHour => 3600,
            Expiry::OneDay => 86_400,
            Expiry::ThirtyDays => 30 * 86_400,
        }
    }

    /// Parses `1h`, `1d` or `30d`.
    pub fn parse(text: &str) -> Result<Expiry, String> {
        Expiry::ALL
            .into_iter()
            .find(|e| e.as_str() == text)
            .ok_or_else(|| format!("expiry `{text}`: expected 1h, 1d or 30d"))
    }
}

/// The answer to `POST /api/shares`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CreatedShare {
    pub id: ShareId,
    /// The secret that deletes the share (`Authorization: Bearer …`); the server keeps only
    /// its SHA-256.
    pub delete_token: String,
    /// When the share expires, RFC 3339 UTC (`2026-12-02T18:25:00Z`).
    pub expires_at: String,
}

/// `GET /api/config`: what a page needs to know before it uploads.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ServerConfig {
    pub api_version: u32,
    /// Largest share accepted, bytes.
    pub max_share_bytes: u64,
    /// The expiries offered.
    pub expiries: Vec<Expiry>,
}

/// An error answer: `{"error": {"kind", "message"}}`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ApiError {
    pub error: ApiErrorBody,
}

/// The body of an [`ApiError`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ApiErrorBody {
    pub kind: ApiErrorKind,
    pub message: String,
}

/// What went wrong, with the HTTP status it comes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ApiErrorKind {
    /// 400: a malformed id, expiry or request.
    BadRequest,
    /// 401: no `Authorization: Bearer` token.
    Unauthorized,
    /// 403: the delete token does not match.
    Forbidden,
    /// 404: no such share (never made, or deleted).
    NotFound,
    /// 410: the share has expired.
    Expired,
    /// 413: the share is larger than the server accepts.
    TooLarge,
    /// 429: too many uploads from this client, or at once.
    RateLimited,
    /// 408: the upload was too slow.
    Timeout,
    /// 507: the store cannot take the share (full, or failing).
    Storage,
}

impl ApiErrorKind {
    /// The HTTP status.
    pub fn status(self) -> u16 {
        match self {
            ApiErrorKind::BadRequest => 400,
            ApiErrorKind::Unauthorized => 401,
            ApiErrorKind::Forbidden => 403,
            ApiErrorKind::NotFound => 404,
            ApiErrorKind::Timeout => 408,
            ApiErrorKind::Expired => 410,
            ApiErrorKind::TooLarge => 413,
            ApiErrorKind::RateLimited => 429,
            ApiErrorKind::Storage => 507,
        }
    }
}

/// The 128-bit AES key of one share, written in links as 22 characters of base64url. It
/// lives only in the link's fragment.
#[derive(Clone, PartialEq, Eq)]
pub struct ShareKey([u8; 16]);

impl fmt::Debug for ShareKey {
    /// Never prints the key.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("ShareKey(…)")
    }
}

impl ShareKey {
    pub fn from_bytes(bytes: [u8; 16]) -> ShareKey {
        ShareKey(bytes)
    }

    pub fn as_bytes(&self) -> &[u8; 16] {
        &self.0
    }

    /// The key as it is written in a link.
    pub fn encode(&self) -> String {
        base64url(&self.0)
    }

    /// Reads a key written by [`ShareKey::encode`].
    pub fn decode(text: &str) -> Result<ShareKey, String> {
        let bytes = from_base64url(text)
            .filter(|b| b.len() == 16 && text.len() == 22)
            .ok_or_else(|| format!("the key `{text}` is not 22 characters of base64url"))?;
        let mut key = [0; 16];
        key.copy_from_slice(&bytes);
        Ok(ShareKey(key))
    }
}

/// Where a link opens the reconstruction: `t=<s>` at `s` seconds from the first frame,
/// `t=<a>-<b>` playing `a`–`b` seconds in a loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkTime {
    /// Seconds from the first frame.
    pub start: f64,
    /// The end of a looped range, seconds.
    pub end: Option<f64>,
}

impl LinkTime {
    /// Parses `12.5` or `3-7.25` (seconds, non-negative, a range increasing).
    pub fn parse(text: &str) -> Result<LinkTime, String> {
        let seconds = |s: &str| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| format!("`t={text}`: expected seconds (`12.5`) or a range (`3-7.25`)"))
        };
        match text.split_once('-') {
            Some((a, b)) => {
                let (start, end) = (seconds(a)?, seconds(b)?);
                if end <= start {
                    return Err(format!("`t={text}`: the range must end after it starts"));
                }
                Ok(LinkTime { start, end: Some(end) })
            }
            None => Ok(LinkTime { start: seconds(text)?, end: None }),
        }
    }
}

impl fmt::Display for LinkTime {
    /// Milliseconds at most: `12.345`, `3-7.25`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = |t: f64| (t * 1000.0).round() / 1000.0;
        match self.end {
            None => write!(f, "{}", ms(self.start)),
            Some(end) => write!(f, "{}-{}", ms(self.start), ms(end)),
        }
    }
}

/// The part of a page address after `#`: `share=<id>.<key>`, `live=<room>.<secret>` (a live
/// room to watch), `t=<time>` and the flag `sample` (open the sample), `&`-separated; other
/// parameters are kept as they are.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkFragment {
    pub share: Option<(ShareId, ShareKey)>,
    pub live: Option<crate::live::LiveLink>,
    pub time: Option<LinkTime>,
    pub sample: bool,
    /// Parameters this version does not know, in order.
    pub other: Vec<String>,
}

impl LinkFragment {
    /// Parses a fragment (with or without its `#`).
    pub fn parse(fragment: &str) -> Result<LinkFragment, String> {
        let mut out = LinkFragment::default();
        for param in fragment.strip_prefix('#').unwrap_or(fragment).split('&').filter(|p| !p.is_empty()) {
            match param.split_once('=') {
                Some(("share", value)) => {
                    let (id, key) =
                        value.split_once('.').ok_or_else(|| format!("`share={value}`: expected <id>.<key>"))?;
                    out.share = Some((ShareId::parse(id)?, ShareKey::decode(key)?));
                }
                Some(("live", value)) => {
                    let link = crate::live::LiveLink::parse_value(value)
                        .ok_or_else(|| format!("`live={value}`: expected <room>.<secret>"))?;
                    out.live = Some(link);
                }
                Some(("t", value)) => out.time = Some(LinkTime::parse(value)?),
                None if param == "sample" => out.sample = true,
                _ => out.other.push(param.to_owned()),
            }
        }
        Ok(out)
    }
}

impl fmt::Display for LinkFragment {
    /// The fragment without its `#` (empty when there is nothing in it).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut params: Vec<String> = Vec::new();
        if let Some((id, key)) = &self.share {
            params.push(format!("share={id}.{}", key.encode()));
        }
        if let Some(live) = &self.live {
            params.push(live.fragment());
        }
        if self.sample {
            params.push("sample".into());
        }
        params.extend(self.other.iter().cloned());
        if let Some(time) = self.time {
            params.push(format!("t={time}"));
        }
        f.write_str(&params.join("&"))
    }
}

/// A share link: `<page>#share=<id>.<key>[&t=<time>]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ShareLink {
    /// The page's address, without fragment (`https://host/`).
    pub page: String,
    pub id: ShareId,
    pub key: ShareKey,
    pub time: Option<LinkTime>,
}

impl ShareLink {
    /// Parses a link (a page address with a `#share=…` fragment).
    pub fn parse(link: &str) -> Result<ShareLink, String> {
        let (page, fragment) =
            link.split_once('#').ok_or_else(|| "the link has no `#share=<id>.<key>` part".to_string())?;
        let fragment = LinkFragment::parse(fragment)?;
        let (id, key) =
            fragment.share.ok_or_else(|| "the link has no `share=<id>.<key>` in its fragment".to_string())?;
        Ok(ShareLink { page: page.to_owned(), id, key, time: fragment.time })
    }

    /// The API address of the share's bytes under the API base `api`:
    /// `<api>/api/shares/<id>`.
    pub fn api_url(&self, api: &str) -> String {
        format!("{}/api/shares/{}", api.trim_end_matches('/'), self.id)
    }

    /// The origin the page was served from (`https://host:port`), the default API base.
    pub fn page_origin(&self) -> Option<&str> {
        let after_scheme = self.page.find("://")? + 3;
        let end = self.page[after_scheme..].find('/').map_or(self.page.len(), |i| after_scheme + i);
        Some(&self.page[..end])
    }
}

impl fmt::Display for ShareLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fragment = LinkFragment {
            share: Some((self.id.clone(), self.key.clone())),
            time: self.time,
            ..LinkFragment::default()
        };
        write!(f, "{}#{fragment}", self.page)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_22_base64url_characters_of_128_bits() {
        let id = ShareId::from_bytes([0xfb; 16]);
        assert_eq!(id.as_str().len(), SHARE_ID_LEN);
        assert_eq!(ShareId::parse(id.as_str()).unwrap(), id);
        assert_eq!(ShareId::from_bytes([0; 16]).as_str(), "AAAAAAAAAAAAAAAAAAAAAA");
        assert_eq!(base64url(b"hello?"), "aGVsbG8_");
        assert_eq!(base64url(&[0xff, 0xee]), "_-4");
        assert_eq!(from_base64url(id.as_str()).unwrap(), [0xfb; 16]);
        for bad in [
            "",
            "short",
            "AAAAAAAAAAAAAAAAAAAAA/",
            "../../../../etc/passwd!",
            "AAAAAAAAAAAAAAAAAAAAAB",
            "AAAAAAAAAAAAAAAAAAAAAAA",
        ] {
            assert!(ShareId::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn links_round_trip_and_keep_the_key_in_the_fragment() {
        let key = ShareKey::from_bytes([0x5a; 16]);
        let id = ShareId::from_bytes([7; 16]);
        let link = ShareLink {
            page: "https://egoexo.example/app/".into(),
            id,
            key,
            time: Some(LinkTime { start: 1.5, end: Some(4.0) }),
        };
        let text = link.to_string();
        let (before, after) = text.split_once('#').unwrap();
        assert_eq!(before, "https://egoexo.example/app/");
        assert!(after.contains(&link.key.encode()) && after.ends_with("&t=1.5-4"), "{after}");
        assert_eq!(ShareLink::parse(&text).unwrap(), link);
        assert_eq!(link.page_origin(), Some("https://egoexo.example"));
        assert_eq!(link.api_url("http://127.0.0.1:8080/"), format!("http://127.0.0.1:8080/api/shares/{}", link.id));
        assert_eq!(format!("{:?}", link.key), "ShareKey(…)");
        let moment = LinkFragment::parse("#sample&t=12.3456").unwrap();
        assert!(moment.sample && moment.share.is_none());
        assert_eq!(moment.to_string(), "sample&t=12.346");
        assert_eq!(LinkFragment::parse("").unwrap(), LinkFragment::default());
        assert_eq!(LinkFragment::parse("#x=1&t=2").unwrap().to_string(), "x=1&t=2");
        // A watch link's room, and a damaged one.
        let watch = LinkFragment::parse("#live=Ab-_9.s3cr3t").unwrap();
        assert_eq!(watch.live.as_ref().map(|l| (l.room.as_str(), l.secret.as_str())), Some(("Ab-_9", "s3cr3t")));
        assert_eq!(watch.to_string(), "live=Ab-_9.s3cr3t");
        assert!(LinkFragment::parse("#live=abc").unwrap_err().contains("<room>.<secret>"));
    }

    #[test]
    fn bad_links_say_what_is_wrong() {
        let id = ShareId::from_bytes([1; 16]);
        let key = ShareKey::from_bytes([2; 16]).encode();
        for (link, needle) in [
            ("https://h/".to_string(), "no `#share"),
            ("https://h/#t=3".to_string(), "no `share="),
            (format!("https://h/#share={id}"), "<id>.<key>"),
            (format!("https://h/#share=nope.{key}"), "not a share id"),
            (format!("https://h/#share={id}.short"), "22 characters"),
            (format!("https://h/#share={id}.{key}&t=5-2"), "end after"),
            (format!("https://h/#share={id}.{key}&t=-1"), "expected seconds"),
        ] {
            let err = ShareLink::parse(&link).unwrap_err();
            assert!(err.contains(needle), "{link}: {err}");
        }
        assert_eq!(LinkTime::parse("12.25").unwrap(), LinkTime { start: 12.25, end: None });
    }

    #[test]
    fn expiries_and_error_bodies_have_their_wire_names() {
        assert_eq!(serde_json::to_value(Expiry::ThirtyDays).unwrap(), "30d");
        assert_eq!(Expiry::parse("1d"), Ok(Expiry::OneDay));
        assert!(Expiry::parse("2d").unwrap_err().contains("1h, 1d or 30d"));
        let err = ApiError { error: ApiErrorBody { kind: ApiErrorKind::TooLarge, message: "x".into() } };
        assert_eq!(
            serde_json::to_value(&err).unwrap(),
            serde_json::json!({"error": {"kind": "too-large", "message": "x"}})
        );
        assert_eq!(ApiErrorKind::Storage.status(), 507);
    }
}
