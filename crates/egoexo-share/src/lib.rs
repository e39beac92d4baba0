//! Share links to a reconstruction (`docs/share-format.md`).
//!
//! A share is what a collaborator needs to see and export a reconstruction without running
//! it: the viewer's scene, the reconstructed motion, the summary, and optionally the
//! recording itself (so it can be re-run). It is packed into a [`container`] (a zip, version
//! [`container::SHARE_FORMAT_VERSION`]), sealed in an [`envelope`] with AES-128-GCM under a
//! fresh random key, and uploaded; the server stores only ciphertext. The [`link`] carries the
//! share's id and the key in the URL *fragment* (`https://host/#share=<id>.<key>`), which
//! browsers never send to a server.
//!
//! Natively (the CLI) the envelope is sealed and opened here with RustCrypto's `aes-gcm`; the
//! browser's worker does the same with WebCrypto on the same layout ([`envelope::parse`],
//! [`envelope::assemble`]).

pub mod container;
pub mod envelope;
pub mod link;

pub use container::{ShareContents, ShareManifest, SharedParticipant, pack, unpack};
pub use link::{LinkFragment, LinkTime, ShareId, ShareKey, ShareLink};

use thiserror::Error;

/// Why a share could not be made or read.
#[derive(Debug, Error)]
pub enum ShareError {
    #[error("not an egoexo share (its first bytes are not the share envelope's)")]
    NotAShare,
    #[error("the share envelope is version {0}; this egoexo reads version {version}", version = envelope::ENVELOPE_VERSION)]
    EnvelopeVersion(u8),
    #[error("the share is sealed with algorithm {0}, which this egoexo does not know")]
    Algorithm(u8),
    #[error("the share is truncated ({0} bytes)")]
    Truncated(usize),
    #[error("cannot decrypt the share: the link's key is wrong, or the share was altered")]
    Decrypt,
    #[error("the share container: {0}")]
    Container(String),
    #[error("the share container is version {found}; this egoexo reads versions 1 to {supported}")]
    ContainerVersion { found: u32, supported: u32 },
    #[error("the share link: {0}")]
    Link(String),
    #[error("no random numbers: {0}")]
    Random(String),
}
