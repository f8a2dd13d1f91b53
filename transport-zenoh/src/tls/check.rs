//! A certificate checked the way the world's router will check it, before it is presented: its
//! common name is the principal's, it is valid now, and the team's authority signed it. Pure
//! functions over PEM bytes and a time, so each refusal is tested without a network.

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rustls::pki_types::{CertificateDer, UnixTime};
use rustls::{CertificateError, RootCertStore};
use x509_parser::pem::parse_x509_pem;

/// What a certificate says about itself.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertificateFacts {
    /// Its subject's common name (the principal it names), when it has one.
    pub common_name: Option<String>,
    /// Valid from, seconds since the Unix epoch.
    pub not_before_unix: i64,
    /// Valid until, seconds since the Unix epoch.
    pub not_after_unix: i64,
    /// `not_after` as text, for messages.
    pub not_after_text: String,
    not_before_text: String,
    der: Vec<u8>,
}

impl CertificateFacts {
    /// Whole days left until it expires at `now`; `None` once expired.
    pub fn days_left(&self, now: SystemTime) -> Option<u64> {
        let left = self.not_after_unix.checked_sub(unix_seconds(now))?;
        u64::try_from(left).ok().map(|s| s / 86_400)
    }
}

/// Why a certificate is not usable for its principal.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CertificateProblem {
    /// Not a PEM certificate.
    #[error(
        "not a PEM certificate ({0}); use the NAME.pem that `formation credentials --tls` wrote"
    )]
    NotPem(String),
    /// The authority file is not a PEM certificate.
    #[error(
        "the team's ca.pem beside it is not a PEM certificate ({0}); copy ca.pem from the folder \
         `formation credentials --tls` wrote"
    )]
    CaNotPem(String),
    /// It names another principal.
    #[error(
        "this is the certificate of {found}, not of {expected} (the world admits a principal by \
         its certificate's common name); use {expected}.pem and {expected}.key.pem"
    )]
    WrongName {
        /// The principal it had to name.
        expected: String,
        /// The common name it holds ("no common name" when it has none).
        found: String,
    },
    /// It expired.
    #[error(
        "the certificate of {principal} expired on {not_after} and the world refuses it: renew it \
         with `formation credentials --tls --renew {principal} --out DIR` (the others stay valid)"
    )]
    Expired {
        /// Its principal.
        principal: String,
        /// When it expired.
        not_after: String,
    },
    /// It is not valid yet.
    #[error(
        "the certificate of {principal} is valid only from {not_before}: is this host's clock \
         right?"
    )]
    NotYetValid {
        /// Its principal.
        principal: String,
        /// When it becomes valid.
        not_before: String,
    },
    /// The team's authority did not sign it.
    #[error(
        "the certificate of {principal} was not issued by the team's ca.pem beside it ({detail}): \
         it comes from another `formation credentials --tls` folder; use the files of one folder"
    )]
    NotFromTheCa {
        /// Its principal.
        principal: String,
        /// What the verifier said.
        detail: String,
    },
}

fn unix_seconds(time: SystemTime) -> i64 {
    match time.duration_since(UNIX_EPOCH) {
        Ok(after) => i64::try_from(after.as_secs()).unwrap_or(i64::MAX),
        Err(before) => -i64::try_from(before.duration().as_secs()).unwrap_or(i64::MAX),
    }
}

/// Reads the first certificate of PEM text `pem`.
pub fn read_facts(pem: &[u8]) -> Result<CertificateFacts, String> {
    let (_, pem) = parse_x509_pem(pem).map_err(|e| e.to_string())?;
    let certificate = pem.parse_x509().map_err(|e| e.to_string())?;
    let common_name = certificate
        .subject()
        .iter_common_name()
        .next()
        .and_then(|cn| cn.as_str().ok())
        .map(str::to_owned);
    let validity = certificate.validity();
    Ok(CertificateFacts {
        common_name,
        not_before_unix: validity.not_before.timestamp(),
        not_after_unix: validity.not_after.timestamp(),
        not_after_text: validity.not_after.to_string(),
        not_before_text: validity.not_before.to_string(),
        der: pem.contents.clone(),
    })
}

/// The cryptography Zenoh 1.10's TLS link installs: rustls with ring (no post-quantum key
/// exchange, which is why rustls 0.23.48 calls it deprecated; Zenoh's own handshakes use it).
#[expect(
    deprecated,
    reason = "the provider Zenoh's TLS link uses, for the same checks"
)]
pub fn ring_provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The first certificate of PEM text `pem`, DER-encoded.
pub fn der_of(pem: &[u8]) -> Result<CertificateDer<'static>, String> {
    let (_, pem) = parse_x509_pem(pem).map_err(|e| e.to_string())?;
    Ok(CertificateDer::from(pem.contents))
}

/// A root store holding the team's authority `ca_pem` alone.
pub fn team_roots(ca_pem: &[u8]) -> Result<RootCertStore, CertificateProblem> {
    let ca = der_of(ca_pem).map_err(CertificateProblem::CaNotPem)?;
    let mut roots = RootCertStore::empty();
    roots
        .add(ca)
        .map_err(|e| CertificateProblem::CaNotPem(e.to_string()))?;
    Ok(roots)
}

/// Checks that `certificate_pem` names `principal`, is valid at `now` and was issued by the
/// authority `ca_pem`, as the world's router will check it.
pub fn check_certificate(
    ca_pem: &[u8],
    certificate_pem: &[u8],
    principal: &str,
    now: SystemTime,
) -> Result<CertificateFacts, CertificateProblem> {
    let roots = team_roots(ca_pem)?;
    let facts = read_facts(certificate_pem).map_err(CertificateProblem::NotPem)?;
    if facts.common_name.as_deref() != Some(principal) {
        return Err(CertificateProblem::WrongName {
            expected: principal.to_string(),
            found: facts
                .common_name
                .clone()
                .unwrap_or_else(|| "no common name".into()),
        });
    }
    let at = unix_seconds(now);
    if at > facts.not_after_unix {
        return Err(CertificateProblem::Expired {
            principal: principal.to_string(),
            not_after: facts.not_after_text.clone(),
        });
    }
    if at < facts.not_before_unix {
        return Err(CertificateProblem::NotYetValid {
            principal: principal.to_string(),
            not_before: facts.not_before_text.clone(),
        });
    }
    verify_chain(roots, &facts.der, now).map_err(|detail| CertificateProblem::NotFromTheCa {
        principal: principal.to_string(),
        detail,
    })?;
    Ok(facts)
}

/// Verifies a client certificate `der` against `roots` (the team's authority alone), with the
/// provider Zenoh's TLS link uses.
fn verify_chain(roots: RootCertStore, der: &[u8], now: SystemTime) -> Result<(), String> {
    let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(
        Arc::new(roots),
        ring_provider(),
    )
    .build()
    .map_err(|e| e.to_string())?;
    let seconds = now
        .duration_since(UNIX_EPOCH)
        .unwrap_or(Duration::ZERO)
        .as_secs();
    let time = UnixTime::since_unix_epoch(Duration::from_secs(seconds));
    verifier
        .verify_client_cert(&CertificateDer::from(der.to_vec()), &[], time)
        .map(|_| ())
        .map_err(|e| match e {
            rustls::Error::InvalidCertificate(CertificateError::UnknownIssuer) => {
                "the authority's signature is not on it".to_string()
            }
            other => other.to_string(),
        })
}

#[cfg(test)]
mod tests {
    use super::super::issue::{Authority, issue_for};
    use super::*;

    const DAY: Duration = Duration::from_secs(86_400);

    #[test]
    fn a_fresh_certificate_of_the_authority_passes_and_says_its_days_left() {
        let now = SystemTime::now();
        let ca = Authority::create(now, 30).unwrap();
        let (cert, _key) = issue_for(&ca, "robot-1", now, 30).unwrap();
        let facts = check_certificate(
            ca.certificate_pem().as_bytes(),
            cert.as_bytes(),
            "robot-1",
            now,
        )
        .expect("valid");
        assert_eq!(facts.common_name.as_deref(), Some("robot-1"));
        assert_eq!(facts.days_left(now), Some(30));
        assert_eq!(facts.days_left(now + Duration::from_secs(2)), Some(29));
        assert_eq!(facts.days_left(now + 31 * DAY), None);
    }

    #[test]
    fn each_refusal_names_its_cause() {
        let now = SystemTime::now();
        let ca = Authority::create(now, 30).unwrap();
        let other = Authority::create(now, 30).unwrap();
        let (robot2, _) = issue_for(&ca, "robot-2", now, 30).unwrap();
        let (old, _) = issue_for(&ca, "robot-1", now - 10 * DAY, 2).unwrap();
        let (foreign, _) = issue_for(&other, "robot-1", now, 30).unwrap();
        let ca_pem = ca.certificate_pem();
        let check =
            |pem: &str| check_certificate(ca_pem.as_bytes(), pem.as_bytes(), "robot-1", now);
        assert!(
            matches!(check(&robot2), Err(CertificateProblem::WrongName { found, .. }) if found == "robot-2")
        );
        let expired = check(&old).unwrap_err();
        assert!(
            matches!(expired, CertificateProblem::Expired { .. }),
            "{expired}"
        );
        assert!(expired.to_string().contains("--renew robot-1"), "{expired}");
        let stranger = check(&foreign).unwrap_err();
        assert!(
            matches!(stranger, CertificateProblem::NotFromTheCa { .. }),
            "{stranger}"
        );
        assert!(matches!(
            check("not pem"),
            Err(CertificateProblem::NotPem(_))
        ));
        let (later, _) = issue_for(&ca, "robot-1", now + 5 * DAY, 30).unwrap();
        assert!(matches!(
            check(&later),
            Err(CertificateProblem::NotYetValid { .. })
        ));
        let bad_ca = check_certificate(b"junk", robot2.as_bytes(), "robot-2", now).unwrap_err();
        assert!(
            matches!(bad_ca, CertificateProblem::CaNotPem(_)),
            "{bad_ca}"
        );
    }
}
