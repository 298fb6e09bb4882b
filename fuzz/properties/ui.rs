//! Properties of the seabus-ui readers that every input must keep. Each function panics when an
//! input breaks a property and tells whether the input was a valid one.

use seabus_ui::Layout;
use std::collections::BTreeMap;

/// The ids of a JSON node and the nodes inside it, in document order.
fn json_ids(node: &serde_json::Value, out: &mut Vec<String>) {
    let id = node["id"]
        .as_str()
        .expect("every JSON node has a string id");
    out.push(id.to_string());
    if let Some(children) = node.get("children").and_then(|c| c.as_array()) {
        for c in children {
            json_ids(c, out);
        }
    }
}

/// The console-layout reader: any text is read or refused without a panic, and a refusal names a
/// place inside the text. A layout that reads has unique ids, each found by `widget`; its JSON
/// form holds the same ids in the same order, and commands; every binding names a widget; it
/// reads the same with a variable given. True when `data` is UTF-8 text that reads as a layout.
pub fn layout(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let layout = match Layout::parse("fuzz.xml", text, &BTreeMap::new()) {
        Ok(l) => l,
        Err(e) => {
            assert_eq!(&*e.pos.file, "fuzz.xml", "{e}");
            let lines: Vec<&str> = text.split('\n').collect();
            let line = usize::try_from(e.pos.line).unwrap_or(usize::MAX);
            let Some(at) = line.checked_sub(1).and_then(|i| lines.get(i)) else {
                panic!("{e} is outside a text of {} lines", lines.len());
            };
            assert!(
                e.pos.col >= 1 && e.pos.col as usize <= at.chars().count() + 1,
                "{e} is outside its line of {} characters",
                at.chars().count()
            );
            return false;
        }
    };
    let ids: Vec<String> = layout.root.walk().iter().map(|n| n.id.clone()).collect();
    for (i, id) in ids.iter().enumerate() {
        assert!(!ids[..i].contains(id), "id `{id}` given twice");
        assert_eq!(
            layout.widget(id).map(|n| n.id.as_str()),
            Some(id.as_str()),
            "widget `{id}` is not found"
        );
    }
    let json = layout.to_json();
    let mut from_json = Vec::new();
    json_ids(&json["root"], &mut from_json);
    assert_eq!(from_json, ids, "the JSON form has other ids");
    let commands = json["commands"]
        .as_object()
        .expect("commands are an object");
    assert_eq!(commands.len(), layout.commands.len());
    for b in layout.bindings() {
        assert!(
            b.widget.starts_with("axis-")
                || b.widget.starts_with("command-")
                || ids.contains(&b.widget),
            "binding of `{}` names no widget: `{}`",
            b.topic,
            b.widget
        );
    }
    for c in layout.commands.values() {
        let sent = c
            .build(
                &seabus_medium::DataMap::new(),
                &seabus_medium::DataMap::new(),
                &Default::default(),
            )
            .unwrap_or_else(|e| panic!("command `{}` refuses its own fields: {e}", c.name));
        assert_eq!(sent, c.fields, "command `{}` sends other fields", c.name);
    }
    let vars: BTreeMap<String, String> = layout.vars.clone();
    let again = Layout::parse("fuzz.xml", text, &vars)
        .unwrap_or_else(|e| panic!("the layout does not read with its own variables: {e}"));
    assert_eq!(
        again, layout,
        "giving the variables' values changes the layout"
    );
    true
}
