//! The browser viewer's files at `/`: served from the viewer folder, gzipped only to browsers
//! that accept it (and marked so for shared caches), revalidated after a rebuild; without a
//! built viewer, `/` is a page naming the build command.

use portico_server::Config;

mod common;
use common::start;

/// A stand-in viewer folder with a small module.
fn viewer(dir: &std::path::Path) {
    common::viewer_folder(dir, b"\0asm plain module");
}

#[tokio::test]
async fn the_viewer_is_served_at_the_root() {
    let dir = tempfile::tempdir().unwrap();
    viewer(dir.path());
    let s = start(Config {
        viewer: Some(dir.path().to_path_buf()),
        ..Config::default()
    })
    .await;
    // No automatic decoding: the test sees the bytes and codings on the wire.
    let http = reqwest::Client::builder().no_gzip().build().unwrap();
    let page = http.get(format!("{}/", s.base)).send().await.unwrap();
    assert_eq!(page.status(), 200);
    assert!(
        page.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    assert_eq!(page.headers()["cache-control"], "no-cache");
    assert!(
        page.text()
            .await
            .unwrap()
            .contains("<title>Portico</title>")
    );

    let wasm = format!("{}/portico_web_bg.wasm", s.base);
    let plain = http.get(&wasm).send().await.unwrap();
    assert_eq!(plain.headers()["content-type"], "application/wasm");
    assert_eq!(plain.headers()["vary"], "accept-encoding");
    assert!(plain.headers().get("content-encoding").is_none());
    assert_eq!(&plain.bytes().await.unwrap()[..], b"\0asm plain module");
    let gz = http
        .get(&wasm)
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(gz.headers()["content-encoding"], "gzip");
    assert_eq!(gz.headers()["vary"], "accept-encoding");
    assert_eq!(&gz.bytes().await.unwrap()[..], b"gzipped module");
    // Only the viewer's own files: nothing else in the folder is reachable.
    std::fs::write(dir.path().join("secret.txt"), "no").unwrap();
    for path in ["/secret.txt", "/portico_web_bg.wasm.gz", "/../Cargo.toml"] {
        let r = http.get(format!("{}{path}", s.base)).send().await.unwrap();
        assert_eq!(r.status(), 404, "{path}");
    }
}

#[tokio::test]
async fn without_a_viewer_the_root_says_how_to_build_one() {
    let s = start(Config::default()).await;
    let r = reqwest::get(format!("{}/", s.base)).await.unwrap();
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    let body = r.text().await.unwrap();
    assert!(body.contains("bash web/build.sh"), "{body}");
    let r = reqwest::get(format!("{}/portico_web_bg.wasm", s.base))
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
}
