//! liblcm, the C library, through the `lcm` crate: messages passed as bytes, untouched, so that
//! tests and benchmarks see exactly what goes over the wire. Shared by the LCM tests and benches.

use std::io::{Read, Write};

/// An LCM message as bytes.
pub struct Raw(pub Vec<u8>);

impl lcm::Message for Raw {
    fn encode_with_hash(&self) -> std::io::Result<Vec<u8>> {
        Ok(self.0.clone())
    }
    fn decode_with_hash(buffer: &mut dyn Read) -> std::io::Result<Self> {
        let mut v = Vec::new();
        buffer.read_to_end(&mut v)?;
        Ok(Raw(v))
    }
    fn encode(&self, buffer: &mut dyn Write) -> std::io::Result<()> {
        buffer.write_all(&self.0)
    }
    fn decode(buffer: &mut dyn Read) -> std::io::Result<Self> {
        Self::decode_with_hash(buffer)
    }
    fn size(&self) -> usize {
        self.0.len()
    }
}

/// Sets the URL liblcm instances created afterwards use; call once, before any is created.
pub fn use_url(url: &str) {
    // SAFETY: called once per process, before liblcm (the only reader) starts
    unsafe { std::env::set_var("LCM_DEFAULT_URL", url) };
}

/// A liblcm instance on the URL given to [`use_url`].
pub fn create() -> lcm::Lcm {
    lcm::Lcm::new().expect("liblcm starts (install liblcm-dev, or run ./scripts/test)")
}
