//! The seed corpora and the campaigns: every checked-in seed, and every seed the real encoders
//! make now, decodes; a short campaign of every target keeps the property (no panic, no hang),
//! with some cases decoded and some refused.

use std::time::Duration;

use formation_fuzz::campaign::{self, Settings};
use formation_fuzz::corpus;
use formation_fuzz::targets::{self, Scratch, Seed, Target};

/// Asserts that each of `seeds` decodes as a case of `target`, naming a failing one
/// `target/name` followed by `hint`.
fn assert_every_seed_decodes(scratch: &Scratch, target: &Target, seeds: &[Seed], hint: &str) {
    for (name, bytes) in seeds {
        assert_eq!(
            (target.run)(scratch, bytes),
            Ok(()),
            "{}/{name}{hint}",
            target.name
        );
    }
}

#[test]
fn every_checked_in_seed_decodes() {
    let scratch = Scratch::new().unwrap();
    for target in targets::ALL {
        let seeds = corpus::load(&corpus::default_root(), target).unwrap();
        assert_every_seed_decodes(
            &scratch,
            target,
            &seeds,
            " does not decode: write the corpora again with `scripts/fuzz seed`",
        );
    }
}

#[test]
fn every_seed_the_encoders_make_now_decodes() {
    let scratch = Scratch::new().unwrap();
    for target in targets::ALL {
        let seeds = (target.seeds)().unwrap();
        assert!(!seeds.is_empty(), "{} makes no seed", target.name);
        assert_every_seed_decodes(&scratch, target, &seeds, "");
    }
}

#[test]
fn a_short_campaign_of_every_target_keeps_the_property() {
    let findings = tempfile::tempdir().unwrap();
    let settings = Settings {
        cases: Some(3000),
        time: None,
        seed: 36,
        findings: findings.path().to_path_buf(),
        hang_after: Duration::from_secs(60),
        ..Settings::default()
    };
    for target in targets::ALL {
        let seeds = corpus::load(&corpus::default_root(), target).unwrap();
        let report = campaign::run(target, &seeds, &settings).unwrap();
        assert_eq!(report.cases, 3000);
        assert!(report.findings.is_empty(), "{:?}", report.findings);
        assert!(
            report.decoded > 0 && report.decoded < report.cases,
            "{}: {} of {} decoded",
            target.name,
            report.decoded,
            report.cases
        );
        assert!(!report.refusals.is_empty());
    }
}

#[test]
fn a_panicking_decoder_is_a_finding_saved_with_its_case() {
    fn panics_on_z(_: &Scratch, case: &[u8]) -> Result<(), targets::Refusal> {
        assert!(!case.contains(&b'z'), "a z");
        Ok(())
    }
    fn seeds() -> Result<Vec<targets::Seed>, formation_fuzz::FuzzError> {
        Ok(vec![("abc".into(), b"abcdefgh".to_vec())])
    }
    static FRAGILE: targets::Target = targets::Target {
        name: "fragile",
        about: "panics on a z",
        run: panics_on_z,
        seeds,
        tokens: &[b"z"],
        shape: formation_fuzz::mutate::Shape::Bytes,
    };
    let findings = tempfile::tempdir().unwrap();
    let settings = Settings {
        cases: Some(2000),
        time: None,
        findings: findings.path().to_path_buf(),
        ..Settings::default()
    };
    let report = campaign::run(&FRAGILE, &seeds().unwrap(), &settings).unwrap();
    let finding = report.findings.first().expect("a case with a z");
    assert!(finding.what.contains("a z"), "{}", finding.what);
    assert!(std::fs::read(&finding.saved).unwrap().contains(&b'z'));
    let again = std::panic::catch_unwind(|| campaign::run_file(&FRAGILE, &finding.saved));
    assert!(again.is_err(), "running the saved case again panics again");
}
