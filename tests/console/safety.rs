//! The operator's safety on the page, driven as a pilot drives it in headless Chromium against the
//! simulated Iver2: a confirmed command sends its own fields whatever was sent before it, the safe
//! action goes from every state of the page, a slider moves only when dragged, and taking control
//! keeps the course the vehicle was on.

use super::common::wait_for_line;
use super::harness::*;
use fantoccini::actions::{
    InputSource, KeyAction, KeyActions, MOUSE_BUTTON_LEFT, MouseActions, PointerAction,
};
use fantoccini::{Client, Locator};
use serde_json::{Value as Json, json};
use std::time::{Duration, Instant};

/// WebDriver's Escape key.
const ESCAPE: char = '\u{E00C}';

/// A pilot's layout with every kind of confirmation on the mission's topic, the safe stop (no key
/// bound: Escape is the safe action's key), a kept course set by a slider and a number box, and
/// a text box.
const SAFETY: &str = r#"<layout name="safety" title="Safety" roles="pilot">
  <command name="course" topic="cmd.course" fields="heading=0.0, depth=0.0, speed=0.0"
           keep="1s" neutral="speed=0" from.heading="nav.attitude.yaw"
           from.depth="nav.depth.depth" from.speed="nav.velocity.speed"
           min.heading="0" max.heading="360" min.depth="0" max.depth="50" min.speed="0"
           max.speed="2.5"/>
  <command name="start" topic="cmd.mission" fields="action=start, name=survey" confirm="dialog"/>
  <command name="begin" topic="cmd.mission" fields="action=start, name=survey" confirm="hold"
           hold="500ms"/>
  <command name="go" topic="cmd.mission" fields="action=start, name=survey"/>
  <command name="abort" topic="cmd.mission" fields="action=abort" confirm="dialog"/>
  <command name="stop" topic="cmd.mission" fields="action=stop" safe="true"/>
  <command name="note" topic="cmd.note" fields="text=none" lease="false"/>
  <column>
    <readout bind="vehicle.state.mode" label="Mode"/>
    <readout bind="vehicle.state.control" label="Control"/>
    <slider id="heading" command="course.heading" min="0" max="360" step="1" label="Heading"/>
    <number id="speed" command="course.speed" min="0" max="2.5" label="Speed"/>
    <text id="note" command="note.text" label="Note"/>
    <row>
      <button id="start" command="start" label="Start"/>
      <button id="begin" command="begin" label="Begin"/>
      <button id="go" command="go" label="Go"/>
      <button id="abort" command="abort" label="Abort"/>
      <button id="stop" command="stop" label="Stop"/>
    </row>
  </column>
</layout>
"#;

/// The Iver2 system with [`SAFETY`] as its console's layout (in the directory that comes with it).
fn safety_system() -> (System, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let layout = dir.path().join("safety.xml");
    std::fs::write(&layout, SAFETY).expect("layout written");
    (start(&[layout]), dir)
}

/// Clicks the button of widget `id`.
async fn click(c: &Client, id: &str) {
    c.find(Locator::Css(&format!("[data-widget-id={id}] button")))
        .await
        .unwrap_or_else(|e| panic!("button {id}: {e}"))
        .click()
        .await
        .expect("clicked");
}

/// The open confirmation dialog's listed fields, once it is open.
async fn dialog_fields(c: &Client) -> String {
    until(
        c,
        Duration::from_secs(5),
        "the confirmation dialog",
        "return document.querySelector('[data-testid=confirm-dialog]').open;",
    )
    .await;
    js(
        c,
        "return document.getElementById('confirm-fields').textContent;",
    )
    .await
    .as_str()
    .unwrap()
    .to_string()
}

/// Confirms the open dialog.
async fn confirm(c: &Client) {
    c.find(Locator::Css("[data-testid=confirm-ok]"))
        .await
        .expect("the dialog's send button")
        .click()
        .await
        .expect("clicked");
}

/// The next `cmd.mission` the bus carries, within 5 s.
fn next_mission(sys: &System, what: &str) -> Json {
    let mut seen = Vec::new();
    wait_for_line(&sys.spy, &mut seen, Duration::from_secs(5), what, |v| {
        v["topic"] == "cmd.mission"
    })
}

/// Waits for the vehicle's control, as the page shows it.
async fn control_is(c: &Client, what: &str) {
    until_eq(
        c,
        Duration::from_secs(15),
        &format!("the vehicle {what}"),
        CONTROL,
        json!(what),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_kind_of_confirmed_button_sends_its_own_fields_whatever_went_before() {
    let (sys, _layouts) = safety_system();
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    control_is(&c, "accepting").await;
    // stop, then start with its dialog: the dialog lists the start's own fields, and they go
    click(&c, "stop").await;
    assert_eq!(
        next_mission(&sys, "the stop")["payload"],
        json!({"action": "stop"})
    );
    control_is(&c, "idle").await;
    click(&c, "start").await;
    assert_eq!(dialog_fields(&c).await, "action = start\nname = survey");
    confirm(&c).await;
    assert_eq!(
        next_mission(&sys, "the start")["payload"],
        json!({"action": "start", "name": "survey"})
    );
    control_is(&c, "accepting").await;
    // after a start, the abort's dialog lists the abort, and the vehicle stops
    click(&c, "abort").await;
    assert_eq!(dialog_fields(&c).await, "action = abort");
    confirm(&c).await;
    assert_eq!(
        next_mission(&sys, "the abort")["payload"],
        json!({"action": "abort"})
    );
    control_is(&c, "idle").await;
    // held to send: the hold button's start after the abort
    js(
        &c,
        "const b = document.querySelector('[data-widget-id=begin] button');
         b.dispatchEvent(new KeyboardEvent('keydown', {bubbles: true, key: ' '}));
         setTimeout(() => b.dispatchEvent(new KeyboardEvent('keyup', {bubbles: true, key: ' '})), 900);
         return true;",
    )
    .await;
    assert_eq!(
        next_mission(&sys, "the held start")["payload"],
        json!({"action": "start", "name": "survey"})
    );
    control_is(&c, "accepting").await;
    // a plain button after a stop
    click(&c, "stop").await;
    assert_eq!(
        next_mission(&sys, "the stop")["payload"],
        json!({"action": "stop"})
    );
    control_is(&c, "idle").await;
    click(&c, "go").await;
    assert_eq!(
        next_mission(&sys, "the plain start")["payload"],
        json!({"action": "start", "name": "survey"})
    );
    control_is(&c, "accepting").await;
    // the console's command log holds every one of them, none refused
    let log = std::fs::read_to_string(sys.dir.join("commands.csv")).expect("the command log");
    let missions: Vec<&str> = log.lines().filter(|l| l.contains("cmd.mission")).collect();
    assert!(missions.len() >= 6, "{log}");
    assert!(!log.contains("refused"), "{log}");
}

/// Presses Escape in whatever has the focus, and waits for the stop on the bus: how long it took.
async fn escape_stops(c: &Client, sys: &System, what: &str) -> Duration {
    while sys.spy.try_recv().is_ok() {}
    let t = Instant::now();
    c.perform_actions(
        KeyActions::new("keyboard".into())
            .then(KeyAction::Down { value: ESCAPE })
            .then(KeyAction::Up { value: ESCAPE }),
    )
    .await
    .expect("Escape pressed");
    let mut seen = Vec::new();
    wait_for_line(&sys.spy, &mut seen, Duration::from_secs(5), what, |v| {
        v["topic"] == "cmd.mission" && v["payload"]["action"] == "stop"
    });
    let took = t.elapsed();
    assert!(
        seen.iter()
            .all(|v| v["topic"] != "cmd.mission" || v["payload"]["action"] == "stop"),
        "only the stop on the mission: {seen:?}"
    );
    println!(
        "{what}: the stop on the bus {} ms after Escape",
        took.as_millis()
    );
    took
}

/// The centre of the knob of slider `id`, in viewport pixels, and the slider's box.
async fn knob(c: &Client, id: &str) -> (f64, f64, f64) {
    let at = js(
        c,
        &format!(
            "const r = document.querySelector('[data-widget-id={id}] input[type=range]');
             const b = r.getBoundingClientRect();
             const f = (parseFloat(r.value) - parseFloat(r.min)) / (parseFloat(r.max) - parseFloat(r.min));
             return [b.left + 8 + f * (b.width - 16), b.top + b.height / 2, b.width];"
        ),
    )
    .await;
    (
        at[0].as_f64().unwrap(),
        at[1].as_f64().unwrap(),
        at[2].as_f64().unwrap(),
    )
}

async fn slider_value(c: &Client, id: &str) -> f64 {
    js(
        c,
        &format!(
            "return parseFloat(document.querySelector('[data-widget-id={id}] input[type=range]').value);"
        ),
    )
    .await
    .as_f64()
    .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn escape_stops_from_every_state_of_the_page() {
    let (sys, _layouts) = safety_system();
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    control_is(&c, "accepting").await;
    // the header's stop is there, named with its key
    let header = js(
        &c,
        "const b = document.querySelector('[data-testid=header-stop]'); return [b.hidden, b.textContent];",
    )
    .await;
    assert_eq!(header, json!([false, "stop (Esc)"]));
    let mut took = Vec::new();
    // right after a speed typed and sent with Enter, the focus still in the number box
    let speed = c
        .find(Locator::Css("[data-widget-id=speed] input[type=number]"))
        .await
        .expect("the speed box");
    speed.clear().await.expect("cleared");
    speed.send_keys("1.2\u{E007}").await.expect("typed");
    let mut seen = Vec::new();
    wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "the course",
        |v| v["topic"] == "cmd.course" && v["payload"]["speed"] == 1.2,
    );
    let focused = js(&c, "return document.activeElement.type;").await;
    assert_eq!(focused, "number");
    took.push(escape_stops(&c, &sys, "focus in a number box").await);
    // with text typed (not sent) in a text box
    let note = c
        .find(Locator::Css("[data-widget-id=note] input"))
        .await
        .expect("the note box");
    note.send_keys("half typed").await.expect("typed");
    took.push(escape_stops(&c, &sys, "focus in a text box").await);
    let notes = commands_on(&sys.spy, "cmd.note", Duration::from_millis(500));
    assert!(notes.is_empty(), "what was typed is not sent: {notes:?}");
    // a confirmation dialog open: it closes, and what it asked is never sent
    click(&c, "abort").await;
    dialog_fields(&c).await;
    took.push(escape_stops(&c, &sys, "a dialog open").await);
    let open = js(
        &c,
        "return document.querySelector('[data-testid=confirm-dialog]').open;",
    )
    .await;
    assert_eq!(open, false);
    let missions = commands_on(&sys.spy, "cmd.mission", Duration::from_secs(2));
    assert!(missions.is_empty(), "no abort after the stop: {missions:?}");
    // mid-hold: the hold is cancelled and its start never goes
    js(
        &c,
        "const b = document.querySelector('[data-widget-id=begin] button');
         b.focus();
         b.dispatchEvent(new KeyboardEvent('keydown', {bubbles: true, key: ' '}));
         return true;",
    )
    .await;
    took.push(escape_stops(&c, &sys, "a hold under way").await);
    let missions = commands_on(&sys.spy, "cmd.mission", Duration::from_secs(2));
    assert!(missions.is_empty(), "no start after the stop: {missions:?}");
    // mid-drag of the heading slider: the drag ends, and letting go sends nothing
    let (x, y, _) = knob(&c, "heading").await;
    let before = slider_value(&c, "heading").await;
    // towards the side with room (a heading near north has the knob at an end)
    let by = if before > 180.0 { -60.0 } else { 60.0 };
    c.perform_actions(press_and_move(x, y, by))
        .await
        .expect("dragged");
    assert_ne!(
        slider_value(&c, "heading").await,
        before,
        "the knob follows the drag"
    );
    took.push(escape_stops(&c, &sys, "a slider dragged").await);
    c.perform_actions(MouseActions::new("mouse".into()).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    }))
    .await
    .expect("let go");
    let courses = commands_on(&sys.spy, "cmd.course", Duration::from_secs(2));
    assert!(
        courses.is_empty(),
        "nothing sent on letting go: {courses:?}"
    );
    assert_eq!(
        slider_value(&c, "heading").await,
        before,
        "the knob back where the vehicle was commanded"
    );
    println!(
        "Escape to stop on the bus, ms: {:?}",
        took.iter().map(|d| d.as_millis()).collect::<Vec<_>>()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_click_on_a_slider_s_track_sends_nothing() {
    let (sys, _layouts) = safety_system();
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    control_is(&c, "accepting").await;
    until(
        &c,
        Duration::from_secs(10),
        "a known heading",
        "return !document.querySelector('[data-widget-id=heading] input[type=range]').disabled;",
    )
    .await;
    let before = slider_value(&c, "heading").await;
    let (x, y, width) = knob(&c, "heading").await;
    // a third of the track away from the knob
    let away = if before > 180.0 {
        x - width / 3.0
    } else {
        x + width / 3.0
    };
    while sys.spy.try_recv().is_ok() {}
    c.perform_actions(
        MouseActions::new("mouse".into())
            .then(PointerAction::MoveTo {
                duration: None,
                x: away.round(),
                y: y.round(),
            })
            .then(PointerAction::Down {
                button: MOUSE_BUTTON_LEFT,
            })
            .then(PointerAction::Up {
                button: MOUSE_BUTTON_LEFT,
            }),
    )
    .await
    .expect("clicked");
    let courses = commands_on(&sys.spy, "cmd.course", Duration::from_secs(2));
    assert!(courses.is_empty(), "{courses:?}");
    assert_eq!(slider_value(&c, "heading").await, before);
    // the knob itself still drags, and the course goes on letting go
    let (x, y, _) = knob(&c, "heading").await;
    c.perform_actions(press_and_move(x, y, 40.0).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    }))
    .await
    .expect("dragged");
    let dragged = slider_value(&c, "heading").await;
    assert_ne!(dragged, before);
    let mut seen = Vec::new();
    wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "the dragged course",
        |v| v["topic"] == "cmd.course" && v["payload"]["heading"] == dragged,
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn taking_control_from_a_running_helm_keeps_its_course() {
    let helm = format!(
        r#"{IVER}
  <module name="helm" type="square" medium="bus" tick="1Hz" side="60" speed="1.5" depth="0"
          heading="0"/>"#
    );
    let sys = start_with(&helm, &[repo("configs/console/pilot.xml")]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    // the helm drives the vehicle: the page knows its course and who sent it
    until_eq(
        &c,
        Duration::from_secs(20),
        "the vehicle under the helm",
        CONTROL,
        json!("in-control"),
    )
    .await;
    c.find(Locator::Css("[data-testid=take-control]"))
        .await
        .expect("take button")
        .click()
        .await
        .expect("clicked");
    let said = confirm_take(&c).await;
    let fields = said["fields"].as_str().unwrap();
    assert!(
        fields.starts_with("course kept: depth = 0, heading = 0, speed = 1.5\n")
            && fields.contains("(commanded by ")
            && !fields.contains("this console"),
        "{said}"
    );
    assert!(
        said["text"]
            .as_str()
            .unwrap()
            .contains("goes on with its last course"),
        "{said}"
    );
    until(
        &c,
        Duration::from_secs(5),
        "control",
        "return window.seabusConsole.state().inControl;",
    )
    .await;
    // for a minute the vehicle stays under the backseat's command, on the kept course, sent by
    // the console alone
    while sys.spy.try_recv().is_ok() {}
    let t = Instant::now();
    let mut courses = Vec::new();
    for _ in 0..70 {
        if t.elapsed() >= Duration::from_secs(60) {
            break;
        }
        let control = js(&c, CONTROL).await;
        assert_eq!(
            control,
            "in-control",
            "the vehicle under command {} s after control was taken",
            t.elapsed().as_secs()
        );
        courses.extend(commands_on(&sys.spy, "cmd.course", Duration::from_secs(1)));
    }
    assert!(t.elapsed() >= Duration::from_secs(60));
    assert!(courses.len() >= 50, "{} courses in a minute", courses.len());
    let first = &courses[0]["payload"];
    for course in &courses {
        assert_eq!(&course["payload"]["heading"], &first["heading"], "{course}");
        assert_eq!(&course["payload"]["speed"], &first["speed"], "{course}");
    }
    let kept = js(
        &c,
        "const k = document.querySelector('[data-testid=kept]'); return k && k.innerText;",
    )
    .await;
    assert!(kept.as_str().unwrap_or("").contains("holding"), "{kept}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_log_in_of_the_pilot_logging_out_leaves_the_first_its_control_and_course() {
    let (sys, _layouts) = safety_system();
    let driver = chromedriver();
    // the pilot at the console, and logged in again on a second machine
    let first = browser(&driver).await;
    log_in(&first, &sys.url, "pilot", "pilot-password").await;
    let second = browser(&driver).await;
    log_in(&second, &sys.url, "pilot", "pilot-password").await;
    take_control(&first, "pilot").await;
    control_is(&first, "accepting").await;
    // a course from the first: kept, sent again every second
    let speed = first
        .find(Locator::Css("[data-widget-id=speed] input[type=number]"))
        .await
        .expect("the speed box");
    speed.clear().await.expect("cleared");
    speed.send_keys("0.8\u{E007}").await.expect("typed");
    let kept = "const k = document.querySelector('[data-testid=kept][data-command=course]');
                return k && k.innerText;";
    let holding = until_text(&first, Duration::from_secs(10), "the kept course", kept).await;
    assert!(holding.contains("holding"), "{holding}");
    // the second machine sees the control as another log-in's, and logs out
    until(
        &second,
        Duration::from_secs(5),
        "the lease in the second log-in",
        "const s = window.seabusConsole.state(); return s.lease === 'pilot' && !s.inControl;",
    )
    .await;
    second
        .goto(&format!("{}/logout", sys.url))
        .await
        .expect("logged out");
    // for ten seconds after: the first still holds control, its course still goes, unchanged
    while sys.spy.try_recv().is_ok() {}
    let courses = commands_on(&sys.spy, "cmd.course", Duration::from_secs(10));
    assert!(courses.len() >= 8, "{} courses in 10 s", courses.len());
    assert!(
        courses.iter().all(|c| c["payload"]["speed"] == 0.8),
        "{courses:?}"
    );
    let state = js(&first, STATE).await;
    assert_eq!(
        (&state["lease"], &state["inControl"]),
        (&json!("pilot"), &json!(true)),
        "{state}"
    );
    let holding = js(&first, kept).await;
    assert!(
        holding.as_str().unwrap_or("").contains("holding"),
        "{holding}"
    );
    control_is(&first, "in-control").await;
}

/// The mouse pressed at (`x`, `y`) and moved `by` pixels sideways over 200 ms, still held.
fn press_and_move(x: f64, y: f64, by: f64) -> MouseActions {
    MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x: x.round(),
            y: y.round(),
        })
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        })
        .then(PointerAction::MoveBy {
            duration: Some(Duration::from_millis(200)),
            x: by,
            y: 0.0,
        })
}
