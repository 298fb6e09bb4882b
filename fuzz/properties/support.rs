//! Properties of the supporting modules' declared conversions that every input must keep.

/// The `convert` module's declared conversions: any line is read or refused with a reason, never a
/// panic; a transform that reads gives one value per output, rotations keep a 3-vector's length and
/// the axis swap undoes itself. True when some line reads.
pub fn conversions(data: &[u8]) -> bool {
    use seabus_support::convert::Conversion;
    use seabus_support::frames::{Fields, Kind, Transform};
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    /// Every field is the same number.
    struct All(f64);
    impl Fields for All {
        fn number(&self, _: &str) -> Option<f64> {
            Some(self.0)
        }
    }
    let mut read = false;
    for line in text.lines() {
        if let Ok(c) = Conversion::parse(line) {
            read = true;
            let _ = c.apply(1.5);
        }
        let Ok(t) = Transform::parse(line) else {
            continue;
        };
        read = true;
        assert_eq!(t.inputs.len(), t.outputs.len(), "{line}");
        for x in [0.0, 12.5, -33.3] {
            let out = t.apply(&All(x)).expect("every field is there");
            assert_eq!(out.len(), t.outputs.len(), "{line}");
            match &t.kind {
                // in three dimensions (with two, z is taken as 0 and dropped after)
                Kind::Rotate(..) if out.len() == 3 => {
                    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
                    let before = norm(&vec![x; out.len()]);
                    assert!(
                        (norm(&out) - before).abs() <= 1e-9 * before.max(1.0),
                        "{line}: rotating {x} gave {out:?}"
                    );
                }
                Kind::SwapEnuNed => {
                    let back = t.apply(&Named(&t.inputs, &out)).expect("all there");
                    assert!(back.iter().all(|v| *v == x), "{line}: {out:?} → {back:?}");
                }
                _ => {}
            }
        }
    }
    read
}

/// Fields `names` holding `values`.
struct Named<'a>(&'a [String], &'a [f64]);

impl seabus_support::frames::Fields for Named<'_> {
    fn number(&self, name: &str) -> Option<f64> {
        self.0.iter().position(|n| n == name).map(|i| self.1[i])
    }
}
