//! Which law labelled a dataset's samples ([`LabelLaw`]): the expert's shaping and pair weights,
//! as `formation collect|dagger --label-wheel-accel | --unshaped-labels | --label-pair-band` set
//! them, and whether the law read every pose or each robot's own scan (`--own-scan-labels`,
//! with `--unblock-hidden-pairs`). Stored in the dataset's manifest (absent for the expert's default law, so a dataset
//! collected with it keeps its bytes and id), folded into `dataset_id`, and compared wherever
//! samples are mixed: DAgger refuses to append samples labelled by another law, and the trainer
//! refuses to train on datasets labelled by different laws.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The expert's labelling law, as far as it differs from its default (labels shaped for each
/// robot's own wheel acceleration limit, the neighbour rule's pairs at full weight, computed from
/// every robot's pose).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelLaw {
    /// Labels shaped for this wheel acceleration limit \[m/s²\] whatever a run's own
    /// (`--label-wheel-accel`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shaping_wheel_accel: Option<f64>,
    /// Labels never shaped, the unlimited law's (`--unshaped-labels`).
    #[serde(default, skip_serializing_if = "is_false")]
    pub unshaped: bool,
    /// Pair weights rising smoothly over this witness-ratio band (`--label-pair-band`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pair_weight_band: Option<[f64; 2]>,
    /// Each robot's label is the expert's law applied to the neighbours it detects in its own
    /// scan (`formation_expert::own_scan::OwnView`), not the expert's that reads every pose
    /// (`--own-scan-labels`). The shaping and the pair weights above apply to it alike.
    #[serde(default, skip_serializing_if = "is_false")]
    pub own_scan: bool,
    /// With `own_scan`: a robot that hides two detections from each other, which would hold each
    /// other, steps aside (`formation_expert::ExpertGains::unblock_hidden_pairs`,
    /// `--unblock-hidden-pairs`).
    #[serde(default, skip_serializing_if = "is_false")]
    pub unblock_hidden_pairs: bool,
}

fn is_false(value: &bool) -> bool {
    !*value
}

impl LabelLaw {
    /// Whether this is the expert's default law (nothing stored in the manifest).
    pub fn is_default(&self) -> bool {
        *self == LabelLaw::default()
    }

    /// Feeds the law's fields to `update`, one call a field; nothing for the default law, so a
    /// dataset labelled by it keeps the id it had before the law was recorded.
    pub(crate) fn hash_fields(&self, update: &mut dyn FnMut(&[u8])) {
        if self.is_default() {
            return;
        }
        update(b"labels");
        if let Some(accel) = self.shaping_wheel_accel {
            update(b"shaping_wheel_accel");
            update(&accel.to_le_bytes());
        }
        if self.unshaped {
            update(b"unshaped");
        }
        if let Some([low, high]) = self.pair_weight_band {
            update(b"pair_weight_band");
            update(&low.to_le_bytes());
            update(&high.to_le_bytes());
        }
        if self.own_scan {
            update(b"own_scan");
        }
        if self.unblock_hidden_pairs {
            update(b"unblock_hidden_pairs");
        }
    }
}

impl fmt::Display for LabelLaw {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_default() {
            return f.write_str("the expert's default (shaped for each run's own wheel limit)");
        }
        let mut parts = Vec::new();
        if let Some(accel) = self.shaping_wheel_accel {
            parts.push(format!(
                "shaped for {accel} m/s² (--label-wheel-accel {accel})"
            ));
        }
        if self.unshaped {
            parts.push("unshaped (--unshaped-labels)".to_owned());
        }
        if let Some([low, high]) = self.pair_weight_band {
            parts.push(format!(
                "pair band {low}-{high} (--label-pair-band {low},{high})"
            ));
        }
        if self.own_scan {
            parts.push("each robot's own scan (--own-scan-labels)".to_owned());
        }
        if self.unblock_hidden_pairs {
            parts.push("stepping aside for hidden pairs (--unblock-hidden-pairs)".to_owned());
        }
        f.write_str(&parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hash(law: &LabelLaw) -> Vec<Vec<u8>> {
        let mut fields = Vec::new();
        law.hash_fields(&mut |bytes| fields.push(bytes.to_vec()));
        fields
    }

    #[test]
    fn the_default_law_writes_and_hashes_nothing() {
        let law = LabelLaw::default();
        assert!(law.is_default());
        assert_eq!(serde_json::to_string(&law).unwrap(), "{}");
        assert!(hash(&law).is_empty());
    }

    #[test]
    fn each_law_round_trips_and_hashes_apart() {
        let laws = [
            LabelLaw {
                unshaped: true,
                ..LabelLaw::default()
            },
            LabelLaw {
                shaping_wheel_accel: Some(1.0),
                ..LabelLaw::default()
            },
            LabelLaw {
                unshaped: true,
                pair_weight_band: Some([1.1, 1.5]),
                ..LabelLaw::default()
            },
            LabelLaw {
                own_scan: true,
                ..LabelLaw::default()
            },
            LabelLaw {
                unshaped: true,
                own_scan: true,
                ..LabelLaw::default()
            },
            LabelLaw {
                unshaped: true,
                own_scan: true,
                unblock_hidden_pairs: true,
                ..LabelLaw::default()
            },
        ];
        for law in laws {
            let text = serde_json::to_string(&law).unwrap();
            assert_eq!(
                serde_json::from_str::<LabelLaw>(&text).unwrap(),
                law,
                "{text}"
            );
        }
        let hashes: Vec<_> = laws.iter().map(hash).collect();
        for (i, a) in hashes.iter().enumerate() {
            for b in &hashes[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }

    #[test]
    fn own_scan_labels_are_stored_only_when_set() {
        let own = LabelLaw {
            own_scan: true,
            ..LabelLaw::default()
        };
        assert!(!own.is_default());
        assert_eq!(serde_json::to_string(&own).unwrap(), r#"{"own_scan":true}"#);
        assert_eq!(
            serde_json::from_str::<LabelLaw>(r#"{"own_scan":false}"#).unwrap(),
            LabelLaw::default()
        );
        assert_eq!(hash(&own), [b"labels".to_vec(), b"own_scan".to_vec()]);
        let with_band = LabelLaw {
            pair_weight_band: Some([1.1, 1.5]),
            ..own
        };
        assert_eq!(
            with_band.to_string(),
            "pair band 1.1-1.5 (--label-pair-band 1.1,1.5), each robot's own scan (--own-scan-labels)"
        );
    }

    #[test]
    fn an_unknown_field_is_refused() {
        let err = serde_json::from_str::<LabelLaw>(r#"{"unshapen": true}"#).unwrap_err();
        assert!(err.to_string().contains("unshapen"), "{err}");
    }

    #[test]
    fn the_text_names_the_flags() {
        let law = LabelLaw {
            unshaped: true,
            pair_weight_band: Some([1.1, 1.5]),
            ..LabelLaw::default()
        };
        assert_eq!(
            law.to_string(),
            "unshaped (--unshaped-labels), pair band 1.1-1.5 (--label-pair-band 1.1,1.5)"
        );
    }
}
