//! `egoexo serve` and `egoexo share` as users run them: the real binary as a child process on
//! loopback. A session shared from the CLI comes back byte-exact through `share get`; shares
//! live in a real S3-protocol server (moto, started here) as well as on disk; and a server
//! killed with SIGKILL in the middle of uploads, restarted on the same store, serves every
//! completed share byte-exact and no partial one.
#![cfg(not(target_arch = "wasm32"))]

use crate::common;

use std::io::Read;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{Served, dist, egoexo};
use egoexo_protocol::share::{CreatedShare, ShareId};
use egoexo_test_support::{python, workspace_root};

/// `egoexo serve` with uploads limited only by the tests' own pace.
fn serve(dist: &Path, store: &str, envs: &[(&str, String)]) -> Served {
    common::serve(dist, store, &["--uploads-per-minute", "1000"], envs)
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder().http_status_as_error(false).build().into()
}

fn upload(url: &str, body: ureq::SendBody) -> Result<CreatedShare, String> {
    let mut response = agent().post(format!("{url}/api/shares?expires=1h")).send(body).map_err(|e| e.to_string())?;
    let status = response.status().as_u16();
    let bytes = response.body_mut().read_to_vec().map_err(|e| e.to_string())?;
    if status != 201 {
        return Err(format!("HTTP {status}: {}", String::from_utf8_lossy(&bytes)));
    }
    serde_json::from_slice(&bytes).map_err(|e| e.to_string())
}

fn download(url: &str, id: &ShareId) -> (u16, Vec<u8>) {
    let mut response = agent().get(format!("{url}/api/shares/{id}")).call().unwrap();
    let status = response.status().as_u16();
    (status, response.body_mut().with_config().limit(1 << 30).read_to_vec().unwrap())
}

fn random(len: usize, seed: u64) -> Vec<u8> {
    egoexo_test_support::pseudo_random_bytes(len, seed)
}

#[test]
fn a_session_shared_from_the_cli_comes_back_through_share_get() {
    let dist = dist();
    let store = tempfile::tempdir().unwrap();
    let server = serve(dist.path(), &store.path().display().to_string(), &[]);
    let root = workspace_root();
    let session = root.join("crates/egoexo-web-worker/tests/fixtures/105_36.egoexo");
    let models = root.join("crates/egoexo-infer/tests/fixtures/models");
    let out = egoexo(&[
        "share",
        &session.display().to_string(),
        "--server",
        &server.url,
        "--expires",
        "1h",
        "--models",
        &models.display().to_string(),
    ]);
    let first_stderr = out.stderr.clone();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let link = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert!(link.starts_with(&format!("{}/#share=", server.url)), "{link}");
    assert!(stderr.contains("delete token"), "{stderr}");
    // The key is in the fragment only: nothing stored contains it.
    let key = link.rsplit('.').next().unwrap();
    for entry in std::fs::read_dir(store.path().join("shares")).unwrap() {
        let bytes = std::fs::read(entry.unwrap().path()).unwrap();
        assert!(!bytes.windows(key.len()).any(|w| w == key.as_bytes()));
    }

    let folder = tempfile::tempdir().unwrap();
    let out = egoexo(&["share", "get", &link, "-o", &folder.path().display().to_string()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for file in
        ["share.json", "scene.json", "motion.json", "session.egoexo", "105_36-ego-exo.bvh", "105_36-ego-exo.npz"]
    {
        assert!(folder.path().join(file).is_file(), "{file}");
    }
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(folder.path().join("share.json")).unwrap()).unwrap();
    assert_eq!(manifest["name"], "105_36");
    assert_eq!(manifest["includes_recording"], true);
    assert_eq!(manifest["summary"]["method"], "ego-exo");
    // The recording inside is a session egoexo reads.
    let inspected = egoexo(&["inspect", &folder.path().join("session.egoexo").display().to_string()]);
    assert!(inspected.status.success(), "{}", String::from_utf8_lossy(&inspected.stderr));

    // The downloaded folder is a reconstruction to share again (here without the recording).
    let out = egoexo(&["share", &folder.path().display().to_string(), "--server", &server.url, "--no-recording"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let again = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert_ne!(again, link);
    let second = tempfile::tempdir().unwrap();
    let out = egoexo(&["share", "get", &again, "-o", &second.path().display().to_string()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |dir: &Path, name: &str| std::fs::read(dir.join(name)).unwrap();
    assert_eq!(read(second.path(), "scene.json"), read(folder.path(), "scene.json"));
    assert_eq!(read(second.path(), "105_36-ego-exo.bvh"), read(folder.path(), "105_36-ego-exo.bvh"));
    assert!(!second.path().join("session.egoexo").exists());

    // A changed key does not open it, and says why.
    let mut altered = link.clone();
    let last = altered.pop().unwrap();
    altered.push(if last == 'A' { 'B' } else { 'A' });
    let out = egoexo(&["share", "get", &altered, "-o", &folder.path().join("x").display().to_string()]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("key is wrong") || stderr.contains("not 22 characters"), "{stderr}");

    // `share delete` with the printed token: a wrong token is refused, the right one deletes it.
    let token = stderr_token(&String::from_utf8_lossy(&first_stderr));
    let out = egoexo(&["share", "delete", &link, "--token", "AAAAAAAAAAAAAAAAAAAAAA"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("deleting the share") && stderr.contains("403"), "{stderr}");
    let out = egoexo(&["share", "delete", &link, "--token", &token]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = egoexo(&["share", "get", &link, "-o", &folder.path().join("y").display().to_string()]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("404"), "{stderr}");
}

/// The delete token `egoexo share` printed on stderr.
fn stderr_token(stderr: &str) -> String {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("delete token (keep it to delete the share): "))
        .unwrap_or_else(|| panic!("no delete token in {stderr}"))
        .trim()
        .to_string()
}

/// Bounds a child process's life; killed when dropped.
struct Moto(Child);

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn wait_for_port(port: u16, child: &mut Child) {
    let deadline = Instant::now() + Duration::from_secs(60);
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("the S3 server exited ({status}) before listening");
        }
        assert!(Instant::now() < deadline, "the S3 server did not start listening on {port}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn shares_live_in_a_real_s3_protocol_server_across_restarts() {
    let port = free_port();
    let mut moto = Moto(
        Command::new(python())
            .args(["-m", "moto.server", "-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("moto's S3 server starts (tests/requirements.txt)"),
    );
    wait_for_port(port, &mut moto.0);
    let endpoint = format!("http://127.0.0.1:{port}");
    let created = agent().put(format!("{endpoint}/egoexo-shares")).send_empty().unwrap();
    assert!(created.status().is_success(), "creating the bucket: {}", created.status());
    let envs = [
        ("AWS_ENDPOINT", endpoint.clone()),
        ("AWS_ALLOW_HTTP", "true".to_string()),
        ("AWS_ACCESS_KEY_ID", "egoexo-test".to_string()),
        ("AWS_SECRET_ACCESS_KEY", "egoexo-test".to_string()),
        ("AWS_REGION", "us-east-1".to_string()),
        ("AWS_VIRTUAL_HOSTED_STYLE_REQUEST", "false".to_string()),
    ];
    let dist = dist();
    let store = "s3://egoexo-shares/deployment-a";
    let mut kept = Vec::new();
    {
        let server = serve(dist.path(), store, &envs);
        for i in 0..3 {
            let bytes = random(200_000 + i * 1000, i as u64);
            let created = upload(&server.url, ureq::SendBody::from_reader(&mut bytes.as_slice())).unwrap();
            assert_eq!(download(&server.url, &created.id), (200, bytes.clone()));
            kept.push((created, bytes));
        }
        let (gone, _) = kept.pop().unwrap();
        let deleted = agent()
            .delete(format!("{}/api/shares/{}", server.url, gone.id))
            .header("Authorization", format!("Bearer {}", gone.delete_token))
            .call()
            .unwrap();
        assert_eq!(deleted.status().as_u16(), 204);
        assert_eq!(download(&server.url, &gone.id).0, 404);
    }
    // The objects are in the bucket under the prefix, as S3 lists them.
    let mut listing = agent().get(format!("{endpoint}/egoexo-shares?prefix=deployment-a/")).call().unwrap();
    let listing = listing.body_mut().read_to_string().unwrap();
    for (created, _) in &kept {
        assert!(listing.contains(&format!("deployment-a/shares/{}.data", created.id)), "{listing}");
    }
    let server = serve(dist.path(), store, &envs);
    for (created, bytes) in &kept {
        assert_eq!(download(&server.url, &created.id), (200, bytes.clone()), "after a restart");
    }
}

/// Sends a body slowly: `chunk` bytes every `pause`.
struct Slow {
    data: Vec<u8>,
    at: usize,
    chunk: usize,
    pause: Duration,
}

impl Read for Slow {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.at >= self.data.len() {
            return Ok(0);
        }
        std::thread::sleep(self.pause);
        let n = self.chunk.min(buf.len()).min(self.data.len() - self.at);
        buf[..n].copy_from_slice(&self.data[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

fn records(store: &Path) -> Vec<PathBuf> {
    let dir = store.join("shares");
    let Ok(entries) = std::fs::read_dir(&dir) else { return Vec::new() };
    entries.map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|x| x == "json")).collect()
}

#[test]
fn a_server_killed_mid_upload_keeps_every_completed_share_and_no_partial_one() {
    let dist = dist();
    let store = tempfile::tempdir().unwrap();
    let store_arg = store.path().display().to_string();
    let server = serve(dist.path(), &store_arg, &[]);
    let url = server.url.clone();
    // Slow uploads still sending when the server dies.
    let slow: Vec<_> = (0..5)
        .map(|i| {
            let url = url.clone();
            std::thread::spawn(move || {
                let data = random(3 << 20, 100 + i);
                let mut body = Slow { data, at: 0, chunk: 64 << 10, pause: Duration::from_millis(40) };
                upload(&url, ureq::SendBody::from_reader(&mut body))
            })
        })
        .collect();
    // Quick uploads that complete before it dies.
    let mut completed = Vec::new();
    for i in 0..6 {
        let bytes = random(500_000, i);
        let created = upload(&url, ureq::SendBody::from_reader(&mut bytes.as_slice())).unwrap();
        completed.push((created, bytes));
    }
    std::thread::sleep(Duration::from_millis(300));
    drop(server); // SIGKILL (Child::kill), mid-way through the slow uploads
    for thread in slow {
        let result = thread.join().unwrap();
        assert!(result.is_err(), "a slow upload finished before the kill: {result:?}");
    }

    let server = serve(dist.path(), &store_arg, &[]);
    for (created, bytes) in &completed {
        assert_eq!(download(&server.url, &created.id), (200, bytes.clone()), "completed share {}", created.id);
    }
    // Exactly the completed shares exist, each complete.
    let found = records(store.path());
    assert_eq!(found.len(), completed.len(), "{found:?}");
    for record in found {
        let meta: serde_json::Value = serde_json::from_slice(&std::fs::read(&record).unwrap()).unwrap();
        let data = std::fs::metadata(record.with_extension("data")).unwrap();
        assert_eq!(Some(data.len()), meta["bytes"].as_u64(), "{}", record.display());
    }
    eprintln!(
        "CRASH killed with 5 uploads in flight; {} completed shares read back byte-exact, 0 partial visible",
        completed.len()
    );
}
