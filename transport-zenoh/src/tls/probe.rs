//! One TLS handshake of our own with the world before Zenoh connects, so that a refusal is an
//! error naming its cause within seconds rather than Zenoh's silent retries.
//!
//! The probe trusts the team's `ca.pem` alone (Zenoh's client adds the public web roots) and
//! checks the world's certificate names `world` (Zenoh would compare the name with the
//! endpoint's host, an IP address). It presents the principal's certificate; a router that
//! refuses it answers with a TLS alert right after the handshake (TLS 1.3 checks the client's
//! certificate last), which the probe waits for during [`REFUSAL_WINDOW`].

use std::io::Read as _;
use std::net::{TcpStream, ToSocketAddrs as _};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{PrivateKeyDer, ServerName};
use rustls::{AlertDescription, CertificateError, ClientConfig, ClientConnection};

use super::check::{der_of, ring_provider, team_roots};
use super::{LoadedIdentity, WORLD_PRINCIPAL};

/// How long a handshake's refusal is waited for once the handshake completed.
pub const REFUSAL_WINDOW: Duration = Duration::from_millis(1000);

/// Why the world's TLS endpoint was not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProbeFailure {
    /// Nothing accepted a TCP connection in time.
    #[error(
        "nothing accepted a connection at {endpoint} within {waited_s:.1} s: is the world \
         running there (`formation-world --transport zenoh --listen {endpoint}`), and is that \
         address reachable from this host?"
    )]
    NothingListening {
        /// The endpoint.
        endpoint: String,
        /// How long this process tried.
        waited_s: f64,
    },
    /// The world's router refused this principal's certificate.
    #[error(
        "the world at {endpoint} refused the certificate of {principal}: {cause} (TLS alert: {alert})"
    )]
    RefusedByWorld {
        /// The endpoint.
        endpoint: String,
        /// Whose certificate.
        principal: String,
        /// What the refusal means.
        cause: String,
        /// The alert the router sent.
        alert: String,
    },
    /// The server's certificate is not the team's world's.
    #[error("the server at {endpoint} is not this team's world: {cause}")]
    NotTheWorld {
        /// The endpoint.
        endpoint: String,
        /// What is wrong with its certificate.
        cause: String,
    },
    /// No TLS handshake completed.
    #[error(
        "no TLS handshake with {endpoint} within {waited_s:.1} s ({detail}): does the world \
         listen on a tls/ endpoint there (not tcp/)?"
    )]
    NoHandshake {
        /// The endpoint.
        endpoint: String,
        /// How long this process tried.
        waited_s: f64,
        /// What happened.
        detail: String,
    },
    /// The principal's own files are not usable for a handshake.
    #[error("cannot use the TLS credentials of {principal}: {detail}")]
    Credentials {
        /// Whose.
        principal: String,
        /// What is wrong.
        detail: String,
    },
}

/// What a refusal alert from the world means for `principal`.
fn refusal_cause(alert: AlertDescription, principal: &str) -> String {
    match alert {
        AlertDescription::UnknownCA | AlertDescription::BadCertificate => format!(
            "the world does not trust the authority that signed it: the world and {principal} \
             hold credentials of different teams (use the files of one `formation credentials \
             --tls` folder)"
        ),
        AlertDescription::CertificateExpired => format!(
            "it expired; renew it with `formation credentials --tls --renew {principal} --out DIR`"
        ),
        AlertDescription::CertificateRequired => {
            "the world requires a certificate and none was presented".into()
        }
        AlertDescription::CertificateRevoked | AlertDescription::AccessDenied => {
            "the world denies it".into()
        }
        other => format!("the world ended the handshake ({other:?})"),
    }
}

/// What a failed check of the world's certificate means.
fn untrusted_world_cause(error: &CertificateError) -> String {
    match error {
        CertificateError::UnknownIssuer | CertificateError::BadSignature => {
            "its certificate was not issued by this team's ca.pem (another team's world, or an \
             impostor)"
                .into()
        }
        CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. } => {
            format!(
                "its certificate does not name {WORLD_PRINCIPAL} (another principal's \
                 certificate)"
            )
        }
        CertificateError::Expired | CertificateError::ExpiredContext { .. } => format!(
            "its certificate expired; renew it with `formation credentials --tls --renew \
             {WORLD_PRINCIPAL} --out DIR` and restart the world"
        ),
        other => format!("its certificate is not acceptable ({other:?})"),
    }
}

/// The client configuration: `ca.pem` alone as root, the principal's certificate and key.
fn client_config(identity: &LoadedIdentity, principal: &str) -> Result<ClientConfig, ProbeFailure> {
    let fail = |detail: String| ProbeFailure::Credentials {
        principal: principal.to_string(),
        detail,
    };
    let roots = team_roots(&identity.ca_pem).map_err(|e| fail(e.to_string()))?;
    let certificate = der_of(&identity.certificate_pem).map_err(&fail)?;
    let key = PrivateKeyDer::from_pem_slice(&identity.key_pem)
        .map_err(|e| fail(format!("the private key is not PEM ({e})")))?;
    ClientConfig::builder_with_provider(ring_provider())
        .with_protocol_versions(&[&rustls::version::TLS13])
        .map_err(|e| fail(e.to_string()))?
        .with_root_certificates(roots)
        .with_client_auth_cert(vec![certificate], key)
        .map_err(|e| fail(format!("the key does not fit the certificate ({e})")))
}

/// Connects to `address` (`HOST:PORT`) over TCP, trying until `deadline`.
fn connect_until(address: &str, deadline: Instant) -> Option<TcpStream> {
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let attempt = Duration::from_secs(1)
            .min(left)
            .max(Duration::from_millis(1));
        if let Ok(addresses) = address.to_socket_addrs() {
            for a in addresses {
                if let Ok(stream) = TcpStream::connect_timeout(&a, attempt) {
                    return Some(stream);
                }
            }
        }
        if Instant::now() >= deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(200).min(left));
    }
}

/// The rustls error inside an I/O error of a TLS stream, if any.
fn rustls_error(error: &std::io::Error) -> Option<&rustls::Error> {
    error.get_ref()?.downcast_ref::<rustls::Error>()
}

/// Handshakes with the world at `endpoint` (`tls/HOST:PORT`) as `principal`, trying to reach it
/// for at most `within`; `Ok` once the world accepted the certificate and showed its own.
pub fn probe_world(
    endpoint: &str,
    identity: &LoadedIdentity,
    principal: &str,
    within: Duration,
) -> Result<(), ProbeFailure> {
    let started = Instant::now();
    let deadline = started + within;
    let config = Arc::new(client_config(identity, principal)?);
    let address = endpoint.strip_prefix("tls/").unwrap_or(endpoint);
    let Some(mut tcp) = connect_until(address, deadline) else {
        return Err(ProbeFailure::NothingListening {
            endpoint: endpoint.to_string(),
            waited_s: started.elapsed().as_secs_f64(),
        });
    };
    let no_handshake = |detail: String| ProbeFailure::NoHandshake {
        endpoint: endpoint.to_string(),
        waited_s: started.elapsed().as_secs_f64(),
        detail,
    };
    let left = deadline
        .saturating_duration_since(Instant::now())
        .max(Duration::from_secs(1));
    tcp.set_read_timeout(Some(left))
        .map_err(|e| no_handshake(e.to_string()))?;
    tcp.set_write_timeout(Some(left))
        .map_err(|e| no_handshake(e.to_string()))?;
    let name = ServerName::try_from(WORLD_PRINCIPAL).map_err(|e| no_handshake(e.to_string()))?;
    let mut connection =
        ClientConnection::new(config, name).map_err(|e| no_handshake(e.to_string()))?;
    let classify = |error: std::io::Error| match rustls_error(&error) {
        Some(rustls::Error::AlertReceived(alert)) => ProbeFailure::RefusedByWorld {
            endpoint: endpoint.to_string(),
            principal: principal.to_string(),
            cause: refusal_cause(*alert, principal),
            alert: format!("{alert:?}"),
        },
        Some(rustls::Error::InvalidCertificate(certificate)) => ProbeFailure::NotTheWorld {
            endpoint: endpoint.to_string(),
            cause: untrusted_world_cause(certificate),
        },
        _ => no_handshake(error.to_string()),
    };
    while connection.is_handshaking() {
        connection.complete_io(&mut tcp).map_err(classify)?;
    }
    // The world checks the certificate after the client's last handshake message: a refusal
    // arrives as an alert shortly after.
    tcp.set_read_timeout(Some(REFUSAL_WINDOW))
        .map_err(|e| no_handshake(e.to_string()))?;
    let mut stream = rustls::Stream::new(&mut connection, &mut tcp);
    let mut byte = [0u8; 1];
    match stream.read(&mut byte) {
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            Ok(())
        }
        Err(e) => Err(classify(e)),
        Ok(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_say_what_to_do() {
        let unknown = refusal_cause(AlertDescription::UnknownCA, "robot-1");
        assert!(unknown.contains("different teams"), "{unknown}");
        let expired = refusal_cause(AlertDescription::CertificateExpired, "robot-1");
        assert!(expired.contains("--renew robot-1"), "{expired}");
        let name = untrusted_world_cause(&CertificateError::NotValidForName);
        assert!(name.contains("does not name world"), "{name}");
    }
}
