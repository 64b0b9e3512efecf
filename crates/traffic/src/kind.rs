//! Aircraft kinds: the few shapes Globus draws, chosen from an ICAO type designator.
//!
//! Designators follow ICAO Doc 8643 (e.g. `A320`, `B77W`, `C172`, `EC35`). Only the families
//! that matter for the shape are listed; anything else (or an unknown type) is drawn as a
//! narrow-body airliner, the commonest aircraft above Europe.

/// The shape an aircraft is drawn with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum AircraftKind {
    /// Single- and twin-engine piston or turboprop aircraft.
    Light = 0,
    /// Single-aisle airliners and regional jets.
    NarrowBody = 1,
    /// Twin-aisle airliners.
    WideBody = 2,
    /// Helicopters.
    Helicopter = 3,
}

impl AircraftKind {
    /// Every kind, by its number.
    pub const ALL: [AircraftKind; 4] = [
        AircraftKind::Light,
        AircraftKind::NarrowBody,
        AircraftKind::WideBody,
        AircraftKind::Helicopter,
    ];

    /// The kind of an ICAO type designator (case-insensitive; empty or unknown: narrow-body).
    ///
    /// ```
    /// use globus_traffic::AircraftKind;
    /// assert_eq!(AircraftKind::from_typecode("B77W"), AircraftKind::WideBody);
    /// assert_eq!(AircraftKind::from_typecode("c172"), AircraftKind::Light);
    /// assert_eq!(AircraftKind::from_typecode("EC35"), AircraftKind::Helicopter);
    /// assert_eq!(AircraftKind::from_typecode("A320"), AircraftKind::NarrowBody);
    /// assert_eq!(AircraftKind::from_typecode(""), AircraftKind::NarrowBody);
    /// ```
    pub fn from_typecode(typecode: &str) -> AircraftKind {
        let code = typecode.trim().to_ascii_uppercase();
        let starts = |prefixes: &[&str]| prefixes.iter().any(|p| code.starts_with(p));
        if starts(WIDE_BODY) {
            AircraftKind::WideBody
        } else if starts(HELICOPTER) {
            AircraftKind::Helicopter
        } else if starts(LIGHT) {
            AircraftKind::Light
        } else {
            AircraftKind::NarrowBody
        }
    }

    /// A typical designator of the kind (what `globus traffic synth` writes).
    pub fn typical_typecode(self) -> &'static str {
        match self {
            AircraftKind::Light => "C172",
            AircraftKind::NarrowBody => "A320",
            AircraftKind::WideBody => "B77W",
            AircraftKind::Helicopter => "EC35",
        }
    }

    /// The kind's number (its model slot in the engine).
    pub fn index(self) -> u8 {
        self as u8
    }
}

/// Twin-aisle families (prefixes; `A310` whole, as `A318`/`A319` are single-aisle).
const WIDE_BODY: &[&str] = &[
    "A306", "A30B", "A310", "A33", "A34", "A35", "A38", "B74", "B76", "B77", "B78", "MD11", "DC10",
    "IL96", "L101",
];

/// Helicopter families.
const HELICOPTER: &[&str] = &[
    "EC", "H1", "H2", "H6", "AS3", "AS5", "AS6", "A109", "A119", "A139", "A169", "AW1", "B06",
    "B407", "B412", "B429", "R22", "R44", "R66", "S76", "S92", "BK17", "NH90", "EH10", "MI8",
];

/// Light aircraft families.
const LIGHT: &[&str] = &[
    "C1", "C2", "PA", "P28", "P32", "P46", "SR2", "DA4", "DA6", "DR4", "BE", "M20", "TB", "PC6",
    "PC12", "TBM", "C208", "DHC2", "DHC6", "RV", "G115", "F406",
];
