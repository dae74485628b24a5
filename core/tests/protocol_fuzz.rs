// SPDX-License-Identifier: MIT
//! Property-based fuzzing of the decoders that read bytes from the network or from files a
//! user hands us: the bridge protocol and RVL depth. Hostile input must give an error, never a
//! panic, a hang or an allocation beyond the input's own size.

use proptest::prelude::*;
use webfusion_core::codec::rvl::{rvl_decode, rvl_deflate_decode, rvl_encode};
use webfusion_core::protocol::{Control, Message, PROTOCOL_MAGIC, PROTOCOL_VERSION};

/// Cases per property; CI runs these many (override with PROPTEST_CASES).
const CASES: u32 = 20_000;

fn config() -> ProptestConfig {
    ProptestConfig { cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(CASES), ..ProptestConfig::default() }
}

/// Bytes that start with a valid header and a plausible kind, so the fuzzer reaches the bodies.
fn with_header() -> impl Strategy<Value = Vec<u8>> {
    (prop::sample::select(vec![1_u8, 2, 3, 4, 5, 16, 17, 0, 255]), prop::collection::vec(any::<u8>(), 0..256)).prop_map(|(kind, body)| {
        let mut bytes = PROTOCOL_MAGIC.to_vec();
        bytes.push(PROTOCOL_VERSION);
        bytes.push(kind);
        bytes.extend(body);
        bytes
    })
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn protocol_decoder_never_panics_on_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = Message::decode(&bytes);
    }

    #[test]
    fn protocol_decoder_never_panics_past_the_header(bytes in with_header()) {
        if let Ok(message) = Message::decode(&bytes) {
            // Whatever decodes must re-encode to the same bytes (no two readings of one message).
            prop_assert_eq!(message.encode(), bytes);
        }
    }

    #[test]
    fn controls_round_trip(index in any::<u64>(), rate in 0.0_f32..1000.0, on in any::<bool>()) {
        for control in [Control::Seek(index), Control::Rate(rate), Control::Loop(on)] {
            let message = Message::Control(control);
            prop_assert_eq!(Message::decode(&message.encode()).expect("decoding"), message);
        }
    }

    #[test]
    fn rvl_decoder_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..2048), pixels in 0_usize..(640 * 480)) {
        let _ = rvl_decode(&bytes, pixels);
        let _ = rvl_deflate_decode(&bytes, pixels);
    }

    #[test]
    fn rvl_round_trips_and_rejects_cut_streams(units in prop::collection::vec(prop_oneof![Just(0_u16), any::<u16>(), 500_u16..520], 1..4096)) {
        let bytes = rvl_encode(&units);
        prop_assert_eq!(rvl_decode(&bytes, units.len()).expect("decoding"), units.clone());
        prop_assert!(rvl_decode(&bytes[..bytes.len() / 2], units.len()).is_err(), "half a stream decoded");
    }
}
