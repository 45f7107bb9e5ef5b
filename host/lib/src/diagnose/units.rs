//! The diagnosis in a linear axis's units: a prismatic drive (the EMPS, a ball screw, a
//! linear motor) or a flexure stage measures force [N] and position [m], and the same
//! equations hold with every rotary unit read as its linear one.

use super::{Diagnosis, ParamValue};
use std::collections::BTreeMap;

/// Rotary units and their linear-axis readings, longest first (so that `N·m/rad` is not
/// read as `N·m` followed by `/rad`).
const LINEAR: [(&str, &str); 6] = [
    ("N·m·s/rad", "N·s/m"),
    ("N·m/rad³", "N/m³"),
    ("N·m/rad", "N/m"),
    ("kg·m²", "kg"),
    ("rad/s", "m/s"),
    ("N·m", "N"),
];

/// `text` with every rotary unit of [`LINEAR`] replaced by its linear reading.
pub fn linear_text(text: &str) -> String {
    let mut out = text.to_string();
    for (rotary, linear) in LINEAR {
        out = out.replace(rotary, linear);
    }
    out
}

impl Diagnosis {
    /// Every unit of the diagnosis as a linear axis's (`--linear-axis`): the parameters'
    /// units, and the units quoted in its sentences. A parameter in `rad` is a position,
    /// in `m`, except a ripple's phase (an angle of its cycle).
    pub fn in_linear_axis_units(&mut self) {
        let params = |m: &mut BTreeMap<String, ParamValue>| {
            for (name, p) in m.iter_mut() {
                let phase = name == "phase" || name.ends_with(".phase");
                p.unit = match p.unit.as_str() {
                    "rad" if !phase => "m".to_string(),
                    u => linear_text(u),
                };
            }
        };
        params(&mut self.nominal_parameters);
        for c in self.effects.iter_mut().chain(self.pair.as_mut()) {
            params(&mut c.parameters);
            params(&mut c.structure_parameters);
            c.reason = linear_text(&c.reason);
            for w in &mut c.warnings {
                *w = linear_text(w);
            }
        }
        self.verdict = linear_text(&self.verdict);
        self.refused = self.refused.as_deref().map(linear_text);
        for w in &mut self.warnings {
            *w = linear_text(w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotary_units_read_as_linear_ones_longest_first() {
        assert_eq!(
            linear_text("fc = 2.1e1 N·m, k3 = 1e3 N·m/rad³, Fv = 3 N·m·s/rad, J = 1 kg·m²"),
            "fc = 2.1e1 N, k3 = 1e3 N/m³, Fv = 3 N·s/m, J = 1 kg"
        );
        assert_eq!(
            linear_text("k_0 = 5 N·m/rad at 0.2 rad/s"),
            "k_0 = 5 N/m at 0.2 m/s"
        );
    }
}
