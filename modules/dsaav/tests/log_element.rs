//! A system's `<log>`: it names one DSAAV medium, once, with a port; the runtime starts it.

use seabus_modules::system::{SystemSpec, check};
use seabus_modules::{Catalogue, Registry};

fn registry() -> Registry {
    let mut reg = Registry::new();
    seabus_dsaav::register(&mut reg);
    reg.set_schemes(seabus_medium_dsaav::schemes());
    reg
}

fn checked(text: &str) -> Result<(), String> {
    let spec = SystemSpec::parse("sys.xml", text).map_err(|e| e.to_string())?;
    check(&spec, &registry(), &Catalogue::default())
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn the_log_element_names_one_dsaav_medium() {
    checked(
        r#"<seabus><medium name="bus" url="inproc://"/><medium name="n1" url="dsaav+inproc://v?node=1"/>
<log medium="n1" port="7"/></seabus>"#,
    )
    .unwrap();
    checked(
        r#"<seabus><medium name="n1" url="dsaav+inproc://v?node=1"/><log medium="n1"/></seabus>"#,
    )
    .unwrap();
    let errors = [
        (
            r#"<seabus><medium name="bus" url="inproc://"/><log medium="bus"/></seabus>"#,
            "sys.xml:1:45: <log> sends to the DSAAV logging service: `bus` is not a DSAAV medium (dsaav+eth, dsaav+udp or dsaav+inproc)",
        ),
        (
            r#"<seabus><medium name="bus" url="inproc://"/><log medium="n7"/></seabus>"#,
            "sys.xml:1:45: no medium called `n7`; media: bus",
        ),
        (
            r#"<seabus><medium name="n1" url="dsaav+inproc://v?node=1"/><log medium="n1" port="x"/></seabus>"#,
            "sys.xml:1:75: attribute `port`: `x` is not a port 0–65535",
        ),
        (
            r#"<seabus><medium name="n1" url="dsaav+inproc://v?node=1"/><log medium="n1"/><log medium="n1"/></seabus>"#,
            "sys.xml:1:76: a system has one <log>; the first is at line 1",
        ),
        (
            r#"<seabus><medium name="n1" url="dsaav+inproc://v?node=1"/><log/></seabus>"#,
            "sys.xml:1:58: <log> is missing attribute `medium`",
        ),
    ];
    for (text, want) in errors {
        assert_eq!(checked(text).unwrap_err(), want, "{text}");
    }
    // without the DSAAV crate's service, <log> is an element nobody reads
    let spec = SystemSpec::parse(
        "sys.xml",
        r#"<seabus><medium name="n1" url="inproc://"/><log medium="n1"/></seabus>"#,
    )
    .unwrap();
    let e = check(&spec, &Registry::new(), &Catalogue::default()).unwrap_err();
    assert!(
        e.to_string().contains(
            "unexpected element <log> inside <seabus>; expected <medium>, <module>, <bridge>"
        ),
        "{e}"
    );
}
