//! Log-in as a browser does it: many at once, wrong ones limited, and sessions that outlive a
//! restart of the console (kept in its session file, ended by log-out, by their expiry and by a
//! bad file).

mod common;

use common::{Setup, get, login, open_ws, setup};
use seabus_ui::auth::MAX_FAILURES;
use seabus_ui::users::add_user;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};
use tracing::span;

/// The status of the console's page with `cookie`: 200 with a live session, 303 to `/login`
/// without.
async fn page(s: &Setup, cookie: &str) -> u16 {
    let (status, head) = get(s.addr, "/", cookie).await;
    if status == 303 {
        assert!(head.to_lowercase().contains("location: /login"), "{head}");
    }
    status
}

fn session_file(s: &Setup) -> PathBuf {
    s.dir.join("users.sessions")
}

/// Logs in; the cookie, or a panic naming the answer.
async fn cookie(s: &Setup, name: &str, password: &str) -> String {
    let (status, cookie, head) = login(s.addr, name, password).await;
    assert_eq!(status, 303, "{head}");
    cookie.unwrap_or_else(|| panic!("{name} logged in: {head}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn twelve_right_log_ins_at_once_all_get_a_working_session() {
    let s = setup().await;
    let mut tasks = Vec::new();
    for _ in 0..12 {
        let addr = s.addr;
        tasks.push(tokio::spawn(async move {
            login(addr, "ana", "ana-password").await
        }));
    }
    let mut cookies = Vec::new();
    for t in tasks {
        let (status, cookie, head) = t.await.unwrap();
        assert_eq!(status, 303, "{head}");
        assert!(head.to_lowercase().contains("location: /\r\n"), "{head}");
        cookies.push(cookie.unwrap_or_else(|| panic!("a session: {head}")));
    }
    cookies.sort();
    cookies.dedup();
    assert_eq!(cookies.len(), 12, "each its own session");
    for c in &cookies {
        assert_eq!(page(&s, c).await, 200, "{c}");
    }
    let mut ws = open_ws(s.addr, Some(&cookies[0])).await.unwrap();
    let _ = ws.close(None).await;
    // nothing was counted against the address or the name
    assert!(
        s.console().hub().limiter.refusals().is_empty(),
        "{:?}",
        s.console().hub().limiter.refusals()
    );
    for _ in 0..MAX_FAILURES - 1 {
        let (status, _, head) = login(s.addr, "ana", "wrong").await;
        assert!(status == 303 && head.contains("error=Wrong"), "{head}");
    }
    assert_eq!(
        page(&s, &cookie(&s, "ana", "ana-password").await).await,
        200
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn twenty_wrong_log_ins_are_limited_and_while_limited_the_right_password_is_refused_too() {
    let s = setup().await;
    for i in 0..20 {
        let (status, cookie, head) = login(s.addr, "bo", "guess").await;
        assert!(cookie.is_none(), "{head}");
        if i < MAX_FAILURES {
            assert_eq!(status, 303, "attempt {i}: {head}");
            assert!(head.contains("error=Wrong"), "{head}");
        } else {
            assert_eq!(status, 429, "attempt {i}: {head}");
            assert!(head.to_lowercase().contains("retry-after: "), "{head}");
        }
    }
    // while limited, the right password is refused too: for the name, and from the address
    let (status, cookie, _) = login(s.addr, "bo", "bo-password1").await;
    assert_eq!((status, cookie), (429, None));
    let (status, cookie, _) = login(s.addr, "ana", "ana-password").await;
    assert_eq!((status, cookie), (429, None));
    let counts = s.console().hub().limiter.refusals();
    assert_eq!(counts.get("failed"), Some(&5), "{counts:?}");
    assert_eq!(counts.get("limited"), Some(&17), "{counts:?}");
    assert_eq!(counts.get("busy"), None, "{counts:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_log_ins_made_together_are_limited_together() {
    let s = setup().await;
    let mut tasks = Vec::new();
    for _ in 0..20 {
        let addr = s.addr;
        tasks.push(tokio::spawn(
            async move { login(addr, "bo", "guess").await },
        ));
    }
    let (mut wrong, mut limited) = (0, 0);
    for t in tasks {
        let (status, cookie, head) = t.await.unwrap();
        assert!(cookie.is_none(), "{head}");
        match status {
            // its turn came before the limit: checked, wrong
            303 => {
                assert!(head.contains("error=Wrong"), "{head}");
                wrong += 1;
            }
            // it waited for the checks under way, which reached the limit
            429 => {
                assert!(head.to_lowercase().contains("retry-after: "), "{head}");
                limited += 1;
            }
            _ => panic!("{status}: {head}"),
        }
    }
    assert_eq!((wrong, limited), (MAX_FAILURES, 20 - MAX_FAILURES));
    // names that cannot be users are refused before anything is counted or checked
    let long = "x".repeat(10_000);
    let (status, _, head) = login(s.addr, &long, "guess").await;
    assert_eq!(status, 303, "{head}");
    let counts = s.console().hub().limiter.refusals();
    assert_eq!(counts.get("failed"), Some(&5), "{counts:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_outlive_a_restart_but_not_a_log_out_nor_their_user() {
    let mut s = setup().await;
    let ana = cookie(&s, "ana", "ana-password").await;
    let bo = cookie(&s, "bo", "bo-password1").await;
    let gone = cookie(&s, "ana", "ana-password").await;
    let (status, head) = get(s.addr, "/logout", &gone).await;
    assert_eq!(status, 303, "{head}");
    // the file holds hashes of the tokens, for its owner alone
    let path = session_file(&s);
    let text = std::fs::read_to_string(&path).unwrap();
    for c in [&ana, &bo, &gone] {
        let token = c.trim_start_matches("seabus_session=");
        assert!(!text.contains(token), "{text}");
    }
    assert_eq!(text.matches("<session ").count(), 2, "{text}");
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(&path).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o600, "{mode:o}");

    s.restart().await;
    assert_eq!(page(&s, &ana).await, 200);
    assert_eq!(page(&s, &bo).await, 200);
    assert_eq!(page(&s, &gone).await, 303, "logged out before the restart");
    // the session opens the WebSocket as its user
    let ws = open_ws(s.addr, Some(&ana)).await;
    assert!(ws.is_ok(), "{:?}", ws.err());

    // bo leaves the users file: his session does not come back
    s.stop();
    let users = s.dir.join("users.xml");
    std::fs::remove_file(&users).unwrap();
    add_user(&users, "ana", &["observer".into()], "ana-password").unwrap();
    s.start().await;
    assert_eq!(page(&s, &ana).await, 200);
    assert_eq!(page(&s, &bo).await, 303);
}

/// Replaces the expiry of `user`'s sessions in the session file with `expires`.
fn set_expiry(path: &Path, user: &str, expires: u64) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut changed = 0;
    let out: Vec<String> = text
        .lines()
        .map(|l| match l.find("expires=\"") {
            Some(at) if l.contains(&format!("user=\"{user}\"")) => {
                changed += 1;
                let rest = &l[at + "expires=\"".len()..];
                let end = rest.find('"').unwrap();
                format!("{}expires=\"{expires}\"{}", &l[..at], &rest[end + 1..])
            }
            _ => l.to_string(),
        })
        .collect();
    assert_eq!(changed, 1, "{text}");
    std::fs::write(path, out.join("\n")).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expired_session_in_the_file_is_refused() {
    let mut s = setup().await;
    let ana = cookie(&s, "ana", "ana-password").await;
    let bo = cookie(&s, "bo", "bo-password1").await;
    s.stop();
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs();
    set_expiry(&session_file(&s), "ana", now - 1);
    s.start().await;
    assert_eq!(page(&s, &ana).await, 303, "expired");
    assert_eq!(page(&s, &bo).await, 200, "the other session in the file");
}

/// Collects what is logged at warning level or above on this thread.
#[derive(Clone, Default)]
struct Warnings(Arc<Mutex<Vec<String>>>);

impl tracing::Subscriber for Warnings {
    fn enabled(&self, m: &tracing::Metadata<'_>) -> bool {
        *m.level() <= tracing::Level::WARN
    }
    fn new_span(&self, _: &span::Attributes<'_>) -> span::Id {
        span::Id::from_u64(1)
    }
    fn record(&self, _: &span::Id, _: &span::Record<'_>) {}
    fn record_follows_from(&self, _: &span::Id, _: &span::Id) {}
    fn event(&self, e: &tracing::Event<'_>) {
        let mut line = String::new();
        e.record(&mut |f: &tracing::field::Field, v: &dyn std::fmt::Debug| {
            line += &format!("{f}={v:?} ");
        });
        self.0.lock().unwrap().push(line);
    }
    fn enter(&self, _: &span::Id) {}
    fn exit(&self, _: &span::Id) {}
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupt_session_file_is_warned_of_and_holds_no_sessions() {
    let mut s = setup().await;
    let ana = cookie(&s, "ana", "ana-password").await;
    s.stop();
    let path = session_file(&s);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("token_hash=\"", "token_hash=\"zz", 1)).unwrap();
    let warnings = Warnings::default();
    {
        // the console starts on this thread: its warnings are caught here
        let _caught = tracing::subscriber::set_default(warnings.clone());
        s.start().await;
    }
    let said = warnings.0.lock().unwrap().join("\n");
    let place = format!("{}:3:", path.display());
    assert!(
        said.contains(&place) && said.contains("token_hash") && said.contains("no sessions"),
        "{said}"
    );
    let problems = s.console().hub().sessions.problems();
    assert_eq!(problems.get("session-file"), Some(&1), "{problems:?}");
    assert_eq!(page(&s, &ana).await, 303);
    // log-in works as ever, and the next start reads the file it writes
    let again = cookie(&s, "ana", "ana-password").await;
    s.restart().await;
    assert_eq!(page(&s, &again).await, 200);
    assert!(s.console().hub().sessions.problems().is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_file_others_may_write_is_not_trusted_and_is_made_private_again() {
    use std::os::unix::fs::PermissionsExt;
    let mut s = setup().await;
    let ana = cookie(&s, "ana", "ana-password").await;
    s.stop();
    let path = session_file(&s);
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o666)).unwrap();
    let warnings = Warnings::default();
    {
        let _caught = tracing::subscriber::set_default(warnings.clone());
        s.start().await;
    }
    let said = warnings.0.lock().unwrap().join("\n");
    assert!(said.contains("others may write it (mode 666)"), "{said}");
    assert_eq!(page(&s, &ana).await, 303);
    // the next write makes it private, and the start after trusts it
    let again = cookie(&s, "ana", "ana-password").await;
    s.restart().await;
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    assert_eq!(page(&s, &again).await, 200);
}
