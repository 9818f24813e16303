//! The robot's fingerprint (docs/design.md §5.1): SHA-256 of a canonical
//! serialisation of the *validated* model, the identity a `.tnet` records
//! and every consumer of a net compares with the robot it is given.
//!
//! Canonical, not the file's bytes: comments, whitespace, key order, number
//! spelling (`207e9` or `207000000000.0`) and defaults written out or left
//! implicit do not change it; any physical number does (to the last bit),
//! and so do the routing kind and the `[damping]` table. The name is left
//! out: renaming a robot does not change what a net trained for it does
//! (the `.tnet` records the name beside the fingerprint, for messages).

use sha2::{Digest, Sha256};

use super::{DampingKeys, Robot, Routing};

/// Tag that opens the serialisation: a change of its layout must change
/// every fingerprint rather than collide with the old ones.
const LAYOUT: &[u8] = b"tendril-robot-fingerprint-v1\0";

impl Robot {
    /// SHA-256 of the canonical serialisation (module docs): each number
    /// as its IEEE-754 bits, little-endian, in a fixed order, −0 as +0.
    pub fn fingerprint(&self) -> [u8; 32] {
        let mut h = Sha256::new();
        h.update(LAYOUT);
        let mut num = |x: f64| h.update((x + 0.0).to_le_bytes());
        for x in [
            self.length,
            self.radius,
            self.youngs_modulus,
            self.shear_modulus,
            self.density,
        ] {
            num(x);
        }
        self.gravity.iter().for_each(|&g| num(g));
        num(self.tendons.len() as f64);
        for t in &self.tendons {
            for x in [t.offset, t.angle, t.max_tension, t.min_tension, t.end] {
                num(x);
            }
            match t.routing {
                Routing::Straight => num(0.0),
                Routing::Helical { turns } => {
                    num(1.0);
                    num(turns);
                }
            }
        }
        match self.damping {
            None => num(0.0),
            Some(DampingKeys::Retardation(t)) => {
                num(1.0);
                num(t);
            }
            Some(DampingKeys::Diagonals { bse, bbt }) => {
                num(2.0);
                bse.iter().chain(&bbt).for_each(|&x| num(x));
            }
        }
        h.finalize().into()
    }

    /// The first 12 hex digits of [`Robot::fingerprint`], for messages.
    pub fn short_fingerprint(&self) -> String {
        short_hex(&self.fingerprint())
    }
}

/// The first 12 hex digits of a 32-byte hash.
pub fn short_hex(hash: &[u8; 32]) -> String {
    hash.iter().take(6).map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::super::file::tests::{parse, GOOD};

    #[test]
    fn comments_whitespace_order_and_spelling_do_not_change_the_fingerprint() {
        let base = parse(GOOD).unwrap().fingerprint();
        let restyled = GOOD
            .replace(
                "youngs_modulus = 207e9",
                "# stiff\n  youngs_modulus   =  2.07e11  # Pa",
            )
            .replace("density = 39317.0", "density = 39317")
            .replace("name = \"t\"", "name = \"renamed\"\n\n");
        assert_ne!(restyled, GOOD);
        assert_eq!(parse(&restyled).unwrap().fingerprint(), base);
        // Tables in another order.
        let (head, tendon) = GOOD.split_once("[[tendon]]").unwrap();
        let reordered = format!("{}\n[[tendon]]{tendon}", head.replace("name = \"t\"\n", ""));
        let reordered = format!("name = \"t\"\n{reordered}");
        assert_eq!(parse(&reordered).unwrap().fingerprint(), base);
    }

    #[test]
    fn any_changed_number_changes_the_fingerprint() {
        let base = parse(GOOD).unwrap().fingerprint();
        for (from, to) in [
            ("youngs_modulus = 207e9", "youngs_modulus = 103.5e9"),
            ("length = 0.4", "length = 0.4000001"),
            ("radius = 0.0009", "radius = 0.00091"),
            ("gravity = [9.81, 0.0, 0.0]", "gravity = [0.0, 0.0, -9.81]"),
            ("offset = 0.019", "offset = 0.018"),
            ("max_tension = 10.0", "max_tension = 9.0"),
        ] {
            let changed = GOOD.replace(from, to);
            assert_ne!(changed, GOOD, "{from}");
            let robot = parse(&changed).unwrap();
            assert_ne!(robot.fingerprint(), base, "{from} → {to}");
        }
        let damped = parse(&format!("{GOOD}[damping]\nretardation_s = 0.05\n")).unwrap();
        assert_ne!(damped.fingerprint(), base);
    }
}
