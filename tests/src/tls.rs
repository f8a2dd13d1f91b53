//! A raw Zenoh client of a team on `tls/` (or `tcp/`), with no `formation` code on its path: the
//! impostor, the eavesdropper and the recorder of the TLS tests (issue 36).

use std::path::Path;

use formation_transport_zenoh::credentials::read_login;
use formation_transport_zenoh::tls::{certificate_file, key_file};
use zenoh::Wait;

/// A raw Zenoh client of `endpoint`: `principal`'s login from `logins`, and on a `tls/`
/// endpoint the certificate and key of `tls`'s principal in its folder (none: no certificate),
/// trusting `logins`' `ca.pem`.
pub fn raw_tls_client(
    endpoint: &str,
    logins: &Path,
    principal: &str,
    tls: Option<(&Path, &str)>,
) -> zenoh::Result<zenoh::Session> {
    let login = read_login(&logins.join(format!("{principal}.json")))
        .map_err(|e| format!("reading {principal}'s login: {e}"))?;
    let mut config = crate::raw_client_config(endpoint)?;
    config.insert_json5(
        "transport/auth/usrpwd",
        &format!(
            "{{ user: {:?}, password: {:?} }}",
            login.user(),
            login.password()
        ),
    )?;
    if endpoint.starts_with("tcp/") {
        return zenoh::open(config).wait();
    }
    let ca = logins.join("ca.pem");
    let section = match tls {
        Some((folder, who)) => serde_json::json!({
            "root_ca_certificate": ca,
            "connect_certificate": certificate_file(folder, who),
            "connect_private_key": key_file(folder, who),
            "enable_mtls": true,
            "verify_name_on_connect": false,
        }),
        None => serde_json::json!({
            "root_ca_certificate": ca,
            "enable_mtls": false,
            "verify_name_on_connect": false,
        }),
    };
    config.insert_json5("transport/link/tls", &section.to_string())?;
    zenoh::open(config).wait()
}
