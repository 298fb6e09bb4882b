//! The media compiled into this program: one line per medium family, its cargo feature, its
//! crate and its schemes. A family left out of the build is still named, so that its URLs get
//! "medium `can` is not compiled into this seabus (feature `can`)" rather than "unknown scheme".

use seabus_medium::Schemes;

macro_rules! media {
    ($($feature:literal => $krate:ident [$($scheme:literal),+];)+) => {
        /// The schemes of every medium family compiled in, and the families left out.
        pub fn schemes() -> Schemes {
            let mut schemes = Schemes::new();
            $(
                #[cfg(feature = $feature)]
                $krate::register(&mut schemes);
                #[cfg(not(feature = $feature))]
                schemes.left_out($feature, $feature, &[$($scheme),+]);
            )+
            schemes
        }
    };
}

media! {
    "udp" => seabus_medium_udp ["udp"];
    "serial" => seabus_medium_serial ["serial", "pty"];
    "can" => seabus_medium_can ["slcan", "slcan+pty", "cannelloni", "socketcan"];
    "lcm" => seabus_medium_lcm ["udpm"];
    "dsaav" => seabus_medium_dsaav ["dsaav+eth", "dsaav+udp", "dsaav+inproc"];
    "moos" => seabus_medium_moos ["moos"];
    "zenoh" => seabus_medium_zenoh ["zenoh"];
    "mavlink" => seabus_medium_mavlink ["mavlink"];
}

/// What `seabus --version` says: the version and the media compiled in.
pub fn long_version() -> String {
    let schemes = schemes();
    let mut text = format!("{}\nmedia:", env!("CARGO_PKG_VERSION"));
    for (family, names) in schemes.families() {
        text.push_str(&format!(" {family} ({})", names.join(", ")));
    }
    let out = schemes.families_left_out();
    if !out.is_empty() {
        let out: Vec<String> = out.iter().map(|(f, _)| f.to_string()).collect();
        text.push_str(&format!("\nleft out: {}", out.join(", ")));
    }
    text
}

/// What `seabus schemes` prints: every scheme compiled in with what it opens, then the families
/// left out with their features.
pub fn describe() -> String {
    let schemes = schemes();
    let mut text = String::new();
    for s in schemes.iter() {
        text.push_str(&format!("{:<14} {:<8} {}\n", s.name, s.family, s.summary));
    }
    for (family, feature) in schemes.families_left_out() {
        text.push_str(&format!(
            "not compiled in: {family} (cargo feature `{feature}`)\n"
        ));
    }
    text
}
