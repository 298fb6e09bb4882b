//! Inputs: `<keys>` with their `<key>`s, and `<gamepad>` with its `<axis>`es and `<button>`s,
//! each checked against the command and field it drives.

use super::model::{AxisBinding, KeyBinding, Offset, PadButton};
use super::read::Reader;
use super::values::{bind, count, field_value, finite, no_children};
use seabus_medium::Value;
use seabus_medium::xml::{Attr, Element, FileError};

/// What a `<key>` does to its field: holds a value, or adds a step each press.
type KeyAction = (Option<Value>, Option<f64>);

impl Reader {
    /// The bindings of a `<keys>` element.
    pub(super) fn keys(&self, el: &Element) -> Result<Vec<KeyBinding>, FileError> {
        el.only_attrs(&[])?;
        el.only_children(&["key"])?;
        el.children.iter().map(|k| self.key(k)).collect()
    }

    /// The axes and buttons of a `<gamepad>` element.
    pub(super) fn gamepad(
        &self,
        el: &Element,
    ) -> Result<(Vec<AxisBinding>, Vec<PadButton>), FileError> {
        el.only_attrs(&[])?;
        el.only_children(&["axis", "button"])?;
        let mut axes = Vec::new();
        let mut buttons = Vec::new();
        for c in &el.children {
            if c.name == "axis" {
                axes.push(self.axis(c)?);
            } else {
                buttons.push(self.pad_button(c)?);
            }
        }
        Ok((axes, buttons))
    }

    fn key(&self, el: &Element) -> Result<KeyBinding, FileError> {
        el.only_attrs(&["key", "command", "value", "step"])?;
        no_children(el)?;
        let k = el.required("key")?;
        if k.value.is_empty() {
            return Err(k.error("empty; give a KeyboardEvent.key such as `w`, `ArrowLeft` or ` `"));
        }
        let a = el.required("command")?;
        let (command, field) = self.command_ref(a, None)?;
        let (value, step) = self.key_action(el, &command, field.as_deref())?;
        Ok(KeyBinding {
            key: k.value.clone(),
            command,
            field,
            value,
            step,
            pos: el.pos.clone(),
        })
    }

    /// A `<key>`'s `value` (held) or `step` (each press) for `field` of `command`: one of them
    /// when it sets a field, neither when it sends the command as it is.
    fn key_action(
        &self,
        el: &Element,
        command: &str,
        field: Option<&str>,
    ) -> Result<KeyAction, FileError> {
        match (field, el.attr("value"), el.attr("step")) {
            (_, Some(v), Some(_)) => {
                Err(v.error("give `value` (held) or `step` (each press), not both"))
            }
            (None, Some(x), _) | (None, _, Some(x)) => Err(x.error(format!(
                "`{}` needs a field: write command=\"{command}.FIELD\"",
                x.name
            ))),
            (Some(f), None, None) => Err(el.error(format!(
                "<key> setting `{command}.{f}` needs `value` (held) or `step` (each press)"
            ))),
            (Some(f), Some(v), None) => {
                let parsed = field_value(v.value.trim());
                let value = match self.commands.get(command) {
                    Some(c) => Some(c.fit(f, &parsed).map_err(|e| v.error(e))?),
                    None => None,
                };
                Ok((value, None))
            }
            (Some(f), None, Some(s)) => {
                self.numeric_field(s, command, f)?;
                Ok((None, Some(finite(s)?)))
            }
            (None, None, None) => Ok((None, None)),
        }
    }

    fn axis(&self, el: &Element) -> Result<AxisBinding, FileError> {
        el.only_attrs(&["index", "command", "deadband", "expo", "gain", "offset"])?;
        no_children(el)?;
        let index = count(el.required("index")?, 0, 255)? as usize;
        let a = el.required("command")?;
        let (command, field) = self.command_ref(a, Some(true))?;
        let field = field.unwrap_or_default();
        self.numeric_field(a, &command, &field)?;
        let deadband = unit(el, "deadband", 0.1)?;
        let expo = unit(el, "expo", 0.0)?;
        let gain = el.attr("gain").map(finite).transpose()?.unwrap_or(1.0);
        let offset = match el.attr("offset") {
            None => Offset::Number(0.0),
            Some(a) => offset(a)?,
        };
        Ok(AxisBinding {
            index,
            command,
            field,
            deadband,
            expo,
            gain,
            offset,
            pos: el.pos.clone(),
        })
    }

    fn pad_button(&self, el: &Element) -> Result<PadButton, FileError> {
        el.only_attrs(&["index", "command"])?;
        no_children(el)?;
        let index = count(el.required("index")?, 0, 255)? as usize;
        let (command, _) = self.command_ref(el.required("command")?, Some(false))?;
        Ok(PadButton {
            index,
            command,
            pos: el.pos.clone(),
        })
    }
}

/// Attribute `name` of `el` as a number from 0 up to (not including) 1; `default` without it.
fn unit(el: &Element, name: &str, default: f64) -> Result<f64, FileError> {
    let Some(a) = el.attr(name) else {
        return Ok(default);
    };
    let x = finite(a)?;
    if (0.0..1.0).contains(&x) {
        Ok(x)
    } else {
        Err(a.error(format!(
            "`{}` is not from 0 up to (not including) 1",
            a.value.trim()
        )))
    }
}

/// An axis's `offset`: a number, or `topic.field` to add the current value.
fn offset(a: &Attr) -> Result<Offset, FileError> {
    match a.value.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(Offset::Number(x)),
        _ => {
            let (t, f) = bind(a)?;
            Ok(Offset::Binding(t.as_str().to_string(), f))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{with, wrong_errors};

    #[test]
    fn inputs_are_checked_against_their_commands() {
        let cases = [
            (
                "<keys><key key=\"a\" command=\"course.speed\"/></keys>",
                "4:7: <key> setting `course.speed` needs `value` (held) or `step` (each press)",
            ),
            (
                "<keys><key key=\"a\" command=\"stop\" value=\"1\"/></keys>",
                "4:35: attribute `value`: `value` needs a field: write command=\"stop.FIELD\"",
            ),
            (
                "<gamepad><axis index=\"0\" command=\"course.speed\" deadband=\"1\"/></gamepad>",
                "4:49: attribute `deadband`: `1` is not from 0 up to (not including) 1",
            ),
            (
                "<gamepad><axis index=\"0\" command=\"course.speed\" expo=\"-0.1\"/></gamepad>",
                "4:49: attribute `expo`: `-0.1` is not from 0 up to (not including) 1",
            ),
            (
                "<gamepad><button index=\"x\" command=\"stop\"/></gamepad>",
                "4:18: attribute `index`: `x` is not a whole number from 0 to 255",
            ),
        ];
        let wrong = wrong_errors(&cases, with);
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }
}
