//! The PGNs seabus knows without a database file: the common navigation, power, engine and
//! network PGNs, written from the NMEA 2000 facts as canboat documents them (field order, bit
//! lengths, resolutions, units, identifiers), and the enumerations they name (in part, for the
//! long ones: manufacturers and device functions).
//!
//! | PGN | identifier | what |
//! |---|---|---|
//! | 60928 | `isoAddressClaim` | a device's ISO NAME (manufacturer, function, class) |
//! | 126992 | `systemTime` | date and time |
//! | 127250 | `vesselHeading` | heading, deviation, variation |
//! | 127251 | `rateOfTurn` | rate of turn |
//! | 127257 | `attitude` | yaw, pitch, roll |
//! | 127488 | `engineParametersRapidUpdate` | engine speed, boost, trim |
//! | 127489 | `engineParametersDynamic` | engine temperatures, pressures, hours, alarms (fast-packet) |
//! | 127506 | `dcDetailedStatus` | state of charge, time remaining (fast-packet) |
//! | 127508 | `batteryStatus` | battery voltage, current, temperature |
//! | 128267 | `waterDepth` | depth below the transducer |
//! | 129025 | `positionRapidUpdate` | latitude, longitude |
//! | 129026 | `cogSogRapidUpdate` | course and speed over ground |
//! | 129029 | `gnssPositionData` | GNSS fix: position, altitude, quality, satellites (fast-packet) |
//! | 130306 | `windData` | wind speed and angle |
//! | 130312 | `temperature` | a temperature |
//! | 130316 | `temperatureExtendedRange` | a temperature, finer |

use super::pgn::{
    BitLookup, Database, Field, IndirectLookup, Kind, Lookup, Packet, PgnDef, Repeating,
};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::sync::Arc;

/// canboat's bounds of an angle in radians, written with seven decimals (not π: the database's
/// numbers, to the last digit).
const TWO_PI: f64 = 6.2831852;
#[allow(clippy::approx_constant)]
const HALF_TURN: f64 = 3.1415926;

fn lookup(name: &'static str, values: &[(u64, &'static str)]) -> Arc<Lookup> {
    Arc::new(Lookup {
        name: Cow::Borrowed(name),
        values: values
            .iter()
            .map(|(v, n)| (*v, Cow::Borrowed(*n)))
            .collect(),
    })
}

fn field(
    id: &'static str,
    name: &'static str,
    bits: u32,
    kind: Kind,
    resolution: f64,
    signed: bool,
    unit: &'static str,
) -> Field {
    Field {
        id: Cow::Borrowed(id),
        name: Cow::Borrowed(name),
        bits: Some(bits),
        bit_offset: None,
        resolution,
        offset: 0,
        signed,
        unit: Cow::Borrowed(unit),
        kind,
        range: None,
        matches: None,
    }
}

fn num(
    id: &'static str,
    name: &'static str,
    bits: u32,
    resolution: f64,
    signed: bool,
    unit: &'static str,
) -> Field {
    field(id, name, bits, Kind::Number, resolution, signed, unit)
}

fn look(id: &'static str, name: &'static str, bits: u32, l: &Arc<Lookup>) -> Field {
    field(id, name, bits, Kind::Lookup(l.clone()), 1.0, false, "")
}

fn reserved(id: &'static str, bits: u32) -> Field {
    field(id, "Reserved", bits, Kind::Reserved, 1.0, false, "")
}

fn sid() -> Field {
    num("sid", "SID", 8, 1.0, false, "")
}

fn ranged(mut f: Field, lo: f64, hi: f64) -> Field {
    f.range = Some((lo, hi));
    f
}

/// An angle of 0 to 2π.
fn bearing(id: &'static str, name: &'static str) -> Field {
    ranged(num(id, name, 16, 1e-4, false, "rad"), 0.0, TWO_PI)
}

/// An angle of −π to π.
fn angle(id: &'static str, name: &'static str) -> Field {
    ranged(num(id, name, 16, 1e-4, true, "rad"), -HALF_TURN, HALF_TURN)
}

fn pgn(
    number: u32,
    id: &'static str,
    description: &'static str,
    packet: Packet,
    length: Option<usize>,
    priority: u8,
    mut fields: Vec<Field>,
) -> PgnDef {
    let mut at = 0;
    for f in &mut fields {
        f.bit_offset = Some(at);
        at += f.bits.unwrap_or(0);
    }
    PgnDef {
        pgn: number,
        id: Cow::Borrowed(id),
        description: Cow::Borrowed(description),
        packet,
        length,
        priority: Some(priority),
        fields,
        repeating: Vec::new(),
        fallback: false,
    }
}

/// The enumerations the built-in PGNs name.
struct Lookups {
    direction: Arc<Lookup>,
    system_time: Arc<Lookup>,
    engine_instance: Arc<Lookup>,
    dc_source: Arc<Lookup>,
    gns: Arc<Lookup>,
    gns_method: Arc<Lookup>,
    gns_integrity: Arc<Lookup>,
    wind: Arc<Lookup>,
    temperature: Arc<Lookup>,
    manufacturer: Arc<Lookup>,
    device_class: Arc<Lookup>,
    industry: Arc<Lookup>,
    yes_no: Arc<Lookup>,
    engine_status_1: Arc<BitLookup>,
    engine_status_2: Arc<BitLookup>,
    device_function: Arc<IndirectLookup>,
}

fn bits(name: &'static str, names: &[&'static str]) -> Arc<BitLookup> {
    Arc::new(BitLookup {
        name: Cow::Borrowed(name),
        bits: names
            .iter()
            .enumerate()
            .map(|(b, n)| (b as u32, Cow::Borrowed(*n)))
            .collect(),
    })
}

fn lookups() -> Lookups {
    // every device function canboat names (its LookupIndirectEnumerations, @canboat/pgns 6.0.2)
    let device_function: BTreeMap<(u64, u64), Cow<'static, str>> = [
        (10, 130, "Diagnostic"),
        (10, 140, "Bus Traffic Logger"),
        (20, 110, "Alarm Enunciator"),
        (
            20,
            130,
            "Emergency Position Indicating Radio Beacon (EPIRB)",
        ),
        (20, 135, "Man Overboard"),
        (20, 140, "Voyage Data Recorder"),
        (20, 150, "Camera"),
        (25, 130, "PC Gateway"),
        (25, 131, "NMEA 2000 to Analog Gateway"),
        (25, 132, "Analog to NMEA 2000 Gateway"),
        (25, 133, "NMEA 2000 to Serial Gateway"),
        (25, 135, "NMEA 0183 Gateway"),
        (25, 136, "NMEA Network Gateway"),
        (25, 137, "NMEA 2000 Wireless Gateway"),
        (25, 140, "Router"),
        (25, 150, "Bridge"),
        (25, 160, "Repeater"),
        (30, 130, "Binary Event Monitor"),
        (30, 140, "Load Controller"),
        (30, 141, "AC/DC Input"),
        (30, 150, "Function Controller"),
        (35, 140, "Engine"),
        (35, 141, "DC Generator/Alternator"),
        (35, 142, "Solar Panel (Solar Array)"),
        (35, 143, "Wind Generator (DC)"),
        (35, 144, "Fuel Cell"),
        (35, 145, "Network Power Supply"),
        (35, 151, "AC Generator"),
        (35, 152, "AC Bus"),
        (35, 153, "AC Mains (Utility/Shore)"),
        (35, 154, "AC Output"),
        (35, 160, "Power Converter - Battery Charger"),
        (35, 161, "Power Converter - Battery Charger+Inverter"),
        (35, 162, "Power Converter - Inverter"),
        (35, 163, "Power Converter - DC"),
        (35, 170, "Battery"),
        (35, 180, "Engine Gateway"),
        (40, 130, "Follow-up Controller"),
        (40, 140, "Mode Controller"),
        (40, 150, "Autopilot"),
        (40, 155, "Rudder"),
        (40, 160, "Heading Sensors"),
        (40, 170, "Trim (Tabs)/Interceptors"),
        (40, 180, "Attitude (Pitch, Roll, Yaw) Control"),
        (50, 130, "Engineroom Monitoring"),
        (50, 140, "Engine"),
        (50, 141, "DC Generator/Alternator"),
        (50, 150, "Engine Controller"),
        (50, 151, "AC Generator"),
        (50, 155, "Motor"),
        (50, 160, "Engine Gateway"),
        (50, 165, "Transmission"),
        (50, 170, "Throttle/Shift Control"),
        (50, 180, "Actuator"),
        (50, 190, "Gauge Interface"),
        (50, 200, "Gauge Large"),
        (50, 210, "Gauge Small"),
        (60, 130, "Bottom Depth"),
        (60, 135, "Bottom Depth/Speed"),
        (60, 136, "Bottom Depth/Speed/Temperature"),
        (60, 140, "Ownship Attitude"),
        (60, 145, "Ownship Position (GNSS)"),
        (60, 150, "Ownship Position (Loran C)"),
        (60, 155, "Speed"),
        (60, 160, "Turn Rate Indicator"),
        (60, 170, "Integrated Navigation"),
        (60, 175, "Integrated Navigation System"),
        (60, 190, "Navigation Management"),
        (60, 195, "Automatic Identification System (AIS)"),
        (60, 200, "Radar"),
        (60, 201, "Infrared Imaging"),
        (60, 205, "ECDIS"),
        (60, 210, "ECS"),
        (60, 220, "Direction Finder"),
        (60, 230, "Voyage Status"),
        (70, 130, "EPIRB"),
        (70, 140, "AIS"),
        (70, 150, "DSC"),
        (70, 160, "Data Receiver/Transceiver"),
        (70, 170, "Satellite"),
        (70, 180, "Radio-telephone (MF/HF)"),
        (70, 190, "Radiotelephone"),
        (75, 130, "Temperature"),
        (75, 140, "Pressure"),
        (75, 150, "Fluid Level"),
        (75, 160, "Flow"),
        (75, 170, "Humidity"),
        (80, 130, "Time/Date Systems"),
        (80, 140, "VDR"),
        (80, 150, "Integrated Instrumentation"),
        (80, 160, "General Purpose Displays"),
        (80, 170, "General Sensor Box"),
        (80, 180, "Weather Instruments"),
        (80, 190, "Transducer/General"),
        (80, 200, "NMEA 0183 Converter"),
        (85, 130, "Atmospheric"),
        (85, 160, "Aquatic"),
        (90, 130, "HVAC"),
        (100, 130, "Scale (Catch)"),
        (110, 130, "Button Interface"),
        (110, 135, "Switch Interface"),
        (110, 140, "Analog Interface"),
        (120, 130, "Display"),
        (120, 140, "Alarm Enunciator"),
        (125, 130, "Multimedia Player"),
        (125, 140, "Multimedia Controller"),
    ]
    .into_iter()
    .map(|(c, f, n)| ((c, f), Cow::Borrowed(n)))
    .collect();
    Lookups {
        direction: lookup(
            "DIRECTION_REFERENCE",
            &[(0, "True"), (1, "Magnetic"), (2, "Error")],
        ),
        system_time: lookup(
            "SYSTEM_TIME",
            &[
                (0, "GPS"),
                (1, "GLONASS"),
                (2, "Radio Station"),
                (3, "Local Cesium clock"),
                (4, "Local Rubidium clock"),
                (5, "Local Crystal clock"),
            ],
        ),
        engine_instance: lookup(
            "ENGINE_INSTANCE",
            &[
                (0, "Single Engine or Dual Engine Port"),
                (1, "Dual Engine Starboard"),
            ],
        ),
        dc_source: lookup(
            "DC_SOURCE",
            &[
                (0, "Battery"),
                (1, "Alternator"),
                (2, "Convertor"),
                (3, "Solar cell"),
                (4, "Wind generator"),
            ],
        ),
        gns: lookup(
            "GNS",
            &[
                (0, "GPS"),
                (1, "GLONASS"),
                (2, "GPS+GLONASS"),
                (3, "GPS+SBAS/WAAS"),
                (4, "GPS+SBAS/WAAS+GLONASS"),
                (5, "Chayka"),
                (6, "integrated"),
                (7, "surveyed"),
                (8, "Galileo"),
            ],
        ),
        gns_method: lookup(
            "GNS_METHOD",
            &[
                (0, "no GNSS"),
                (1, "GNSS fix"),
                (2, "DGNSS fix"),
                (3, "Precise GNSS"),
                (4, "RTK Fixed Integer"),
                (5, "RTK float"),
                (6, "Estimated (DR) mode"),
                (7, "Manual Input"),
                (8, "Simulate mode"),
            ],
        ),
        gns_integrity: lookup(
            "GNS_INTEGRITY",
            &[
                (0, "No integrity checking"),
                (1, "Safe"),
                (2, "Caution"),
                (3, "Unsafe"),
            ],
        ),
        wind: lookup(
            "WIND_REFERENCE",
            &[
                (0, "True (ground referenced to North)"),
                (1, "Magnetic (ground referenced to Magnetic North)"),
                (2, "Apparent"),
                (3, "True (boat referenced)"),
                (4, "True (water referenced)"),
            ],
        ),
        temperature: lookup(
            "TEMPERATURE_SOURCE",
            &[
                (0, "Sea Temperature"),
                (1, "Outside Temperature"),
                (2, "Inside Temperature"),
                (3, "Engine Room Temperature"),
                (4, "Main Cabin Temperature"),
                (5, "Live Well Temperature"),
                (6, "Bait Well Temperature"),
                (7, "Refrigeration Temperature"),
                (8, "Heating System Temperature"),
                (9, "Dew Point Temperature"),
                (10, "Apparent Wind Chill Temperature"),
                (11, "Theoretical Wind Chill Temperature"),
                (12, "Heat Index Temperature"),
                (13, "Freezer Temperature"),
                (14, "Exhaust Gas Temperature"),
                (15, "Shaft Seal Temperature"),
            ],
        ),
        manufacturer: lookup(
            "MANUFACTURER_CODE",
            &[
                (135, "Airmar"),
                (137, "Maretron"),
                (140, "Lowrance"),
                (144, "Mercury Marine"),
                (174, "Volvo Penta"),
                (229, "Garmin"),
                (273, "Actisense"),
                (275, "Navico"),
                (358, "Victron Energy"),
                (381, "B & G"),
                (421, "Standard Horizon"),
                (504, "Vesper Marine Ltd"),
                (717, "Yacht Devices"),
                (1851, "Raymarine"),
                (1855, "Furuno"),
                (1857, "Simrad"),
                (1862, "Yamaha Marine"),
            ],
        ),
        device_class: lookup(
            "DEVICE_CLASS",
            &[
                (0, "Reserved for 2000 Use"),
                (10, "System tools"),
                (20, "Safety systems"),
                (25, "Internetwork device"),
                (30, "Electrical Distribution"),
                (35, "Electrical Generation"),
                (40, "Steering and Control surfaces"),
                (50, "Propulsion"),
                (60, "Navigation"),
                (70, "Communication"),
                (75, "Sensor Communication Interface"),
                (80, "Instrumentation/general systems"),
                (85, "External Environment"),
                (90, "Internal Environment"),
                (100, "Deck + cargo + fishing equipment systems"),
                (110, "Human Interface"),
                (120, "Display"),
                (125, "Entertainment"),
            ],
        ),
        industry: lookup(
            "INDUSTRY_CODE",
            &[
                (0, "Global"),
                (1, "Highway"),
                (2, "Agriculture"),
                (3, "Construction"),
                (4, "Marine"),
                (5, "Industrial"),
            ],
        ),
        yes_no: lookup("YES_NO", &[(0, "No"), (1, "Yes")]),
        engine_status_1: bits(
            "ENGINE_STATUS_1",
            &[
                "Check Engine",
                "Over Temperature",
                "Low Oil Pressure",
                "Low Oil Level",
                "Low Fuel Pressure",
                "Low System Voltage",
                "Low Coolant Level",
                "Water Flow",
                "Water In Fuel",
                "Charge Indicator",
                "Preheat Indicator",
                "High Boost Pressure",
                "Rev Limit Exceeded",
                "EGR System",
                "Throttle Position Sensor",
                "Emergency Stop",
            ],
        ),
        engine_status_2: bits(
            "ENGINE_STATUS_2",
            &[
                "Warning Level 1",
                "Warning Level 2",
                "Power Reduction",
                "Maintenance Needed",
                "Engine Comm Error",
                "Sub or Secondary Throttle",
                "Neutral Start Protect",
                "Engine Shutting Down",
            ],
        ),
        device_function: Arc::new(IndirectLookup {
            name: Cow::Borrowed("DEVICE_FUNCTION"),
            values: device_function,
        }),
    }
}

/// The built-in PGN definitions.
pub fn database() -> Database {
    use Packet::{Fast, Single};
    let l = lookups();
    let mut db = Database::new("built-in");
    let claim = vec![
        num("uniqueNumber", "Unique Number", 21, 1.0, false, ""),
        look("manufacturerCode", "Manufacturer Code", 11, &l.manufacturer),
        num(
            "deviceInstanceLower",
            "Device Instance Lower",
            3,
            1.0,
            false,
            "",
        ),
        num(
            "deviceInstanceUpper",
            "Device Instance Upper",
            5,
            1.0,
            false,
            "",
        ),
        field(
            "deviceFunction",
            "Device Function",
            8,
            Kind::IndirectLookup {
                lookup: l.device_function.clone(),
                // the device class, two fields on
                by: 6,
            },
            1.0,
            false,
            "",
        ),
        field("spare", "Spare", 1, Kind::Spare, 1.0, false, ""),
        look("deviceClass", "Device Class", 7, &l.device_class),
        num("systemInstance", "System Instance", 4, 1.0, false, ""),
        look("industryGroup", "Industry Group", 3, &l.industry),
        look(
            "arbitraryAddressCapable",
            "Arbitrary address capable",
            1,
            &l.yes_no,
        ),
    ];
    db.add(pgn(
        60928,
        "isoAddressClaim",
        "ISO Address Claim",
        Single,
        Some(8),
        6,
        claim,
    ));
    db.add(pgn(
        126992,
        "systemTime",
        "System Time",
        Single,
        Some(8),
        3,
        vec![
            sid(),
            look("source", "Source", 4, &l.system_time),
            reserved("reserved", 4),
            field("date", "Date", 16, Kind::Date, 1.0, false, "d"),
            ranged(
                field("time", "Time", 32, Kind::Time, 1e-4, false, "s"),
                0.0,
                86401.0,
            ),
        ],
    ));
    db.add(pgn(
        127250,
        "vesselHeading",
        "Vessel Heading",
        Single,
        Some(8),
        2,
        vec![
            sid(),
            bearing("heading", "Heading"),
            angle("deviation", "Deviation"),
            angle("variation", "Variation"),
            look("reference", "Reference", 2, &l.direction),
            reserved("reserved", 6),
        ],
    ));
    db.add(pgn(
        127251,
        "rateOfTurn",
        "Rate of Turn",
        Single,
        Some(8),
        2,
        vec![
            sid(),
            num("rate", "Rate", 32, 3.125e-8, true, "rad/s"),
            reserved("reserved", 24),
        ],
    ));
    db.add(pgn(
        127257,
        "attitude",
        "Attitude",
        Single,
        Some(8),
        3,
        vec![
            sid(),
            angle("yaw", "Yaw"),
            angle("pitch", "Pitch"),
            angle("roll", "Roll"),
            reserved("reserved", 8),
        ],
    ));
    db.add(pgn(
        127488,
        "engineParametersRapidUpdate",
        "Engine Parameters, Rapid Update",
        Single,
        Some(8),
        2,
        vec![
            look("instance", "Instance", 8, &l.engine_instance),
            num("speed", "Speed", 16, 0.25, false, "rpm"),
            num("boostPressure", "Boost Pressure", 16, 100.0, false, "Pa"),
            num("tiltTrim", "Tilt/Trim", 8, 1.0, true, "%"),
            reserved("reserved", 16),
        ],
    ));
    db.add(pgn(
        127489,
        "engineParametersDynamic",
        "Engine Parameters, Dynamic",
        Fast,
        Some(26),
        2,
        vec![
            look("instance", "Instance", 8, &l.engine_instance),
            num("oilPressure", "Oil pressure", 16, 100.0, false, "Pa"),
            num("oilTemperature", "Oil temperature", 16, 0.1, false, "K"),
            num("temperature", "Temperature", 16, 0.01, false, "K"),
            num(
                "alternatorPotential",
                "Alternator Potential",
                16,
                0.01,
                true,
                "V",
            ),
            num("fuelRate", "Fuel Rate", 16, 0.1, true, "L/h"),
            field(
                "totalEngineHours",
                "Total Engine hours",
                32,
                Kind::Duration,
                1.0,
                false,
                "s",
            ),
            num(
                "coolantPressure",
                "Coolant Pressure",
                16,
                100.0,
                false,
                "Pa",
            ),
            num("fuelPressure", "Fuel Pressure", 16, 1000.0, false, "Pa"),
            reserved("reserved", 8),
            field(
                "discreteStatus1",
                "Discrete Status 1",
                16,
                Kind::BitLookup(l.engine_status_1.clone()),
                1.0,
                false,
                "",
            ),
            field(
                "discreteStatus2",
                "Discrete Status 2",
                16,
                Kind::BitLookup(l.engine_status_2.clone()),
                1.0,
                false,
                "",
            ),
            num("engineLoad", "Engine Load", 8, 1.0, true, "%"),
            num("engineTorque", "Engine Torque", 8, 1.0, true, "%"),
        ],
    ));
    db.add(pgn(
        127506,
        "dcDetailedStatus",
        "DC Detailed Status",
        Fast,
        Some(11),
        6,
        vec![
            sid(),
            num("instance", "Instance", 8, 1.0, false, ""),
            look("dcType", "DC Type", 8, &l.dc_source),
            num("stateOfCharge", "State of Charge", 8, 1.0, false, "%"),
            num("stateOfHealth", "State of Health", 8, 1.0, false, "%"),
            field(
                "timeRemaining",
                "Time Remaining",
                16,
                Kind::Duration,
                60.0,
                false,
                "s",
            ),
            num("rippleVoltage", "Ripple Voltage", 16, 0.001, false, "V"),
            num(
                "remainingCapacity",
                "Remaining capacity",
                16,
                3600.0,
                false,
                "C",
            ),
        ],
    ));
    db.add(pgn(
        127508,
        "batteryStatus",
        "Battery Status",
        Single,
        Some(8),
        6,
        vec![
            num("instance", "Instance", 8, 1.0, false, ""),
            num("voltage", "Voltage", 16, 0.01, true, "V"),
            num("current", "Current", 16, 0.1, true, "A"),
            num("temperature", "Temperature", 16, 0.01, false, "K"),
            sid(),
        ],
    ));
    db.add(pgn(
        128267,
        "waterDepth",
        "Water Depth",
        Single,
        Some(8),
        3,
        vec![
            sid(),
            num("depth", "Depth", 32, 0.01, false, "m"),
            num("offset", "Offset", 16, 0.001, true, "m"),
            num("range", "Range", 8, 10.0, false, "m"),
        ],
    ));
    db.add(pgn(
        129025,
        "positionRapidUpdate",
        "Position, Rapid Update",
        Single,
        Some(8),
        2,
        vec![
            ranged(
                num("latitude", "Latitude", 32, 1e-7, true, "deg"),
                -90.0,
                90.0,
            ),
            ranged(
                num("longitude", "Longitude", 32, 1e-7, true, "deg"),
                -180.0,
                180.0,
            ),
        ],
    ));
    db.add(pgn(
        129026,
        "cogSogRapidUpdate",
        "COG & SOG, Rapid Update",
        Single,
        Some(8),
        2,
        vec![
            sid(),
            look("cogReference", "COG Reference", 2, &l.direction),
            reserved("reserved", 6),
            bearing("cog", "COG"),
            num("sog", "SOG", 16, 0.01, false, "m/s"),
            reserved("reserved6", 16),
        ],
    ));
    let mut gnss = pgn(
        129029,
        "gnssPositionData",
        "GNSS Position Data",
        Fast,
        None,
        3,
        vec![
            sid(),
            field("date", "Date", 16, Kind::Date, 1.0, false, "d"),
            ranged(
                field("time", "Time", 32, Kind::Time, 1e-4, false, "s"),
                0.0,
                86401.0,
            ),
            ranged(
                num("latitude", "Latitude", 64, 1e-16, true, "deg"),
                -90.0,
                90.0,
            ),
            ranged(
                num("longitude", "Longitude", 64, 1e-16, true, "deg"),
                -180.0,
                180.0,
            ),
            num("altitude", "Altitude", 64, 1e-6, true, "m"),
            look("gnssType", "GNSS type", 4, &l.gns),
            look("method", "Method", 4, &l.gns_method),
            look("integrity", "Integrity", 2, &l.gns_integrity),
            reserved("reserved", 6),
            num("numberOfSvs", "Number of SVs", 8, 1.0, false, ""),
            num("hdop", "HDOP", 16, 0.01, true, ""),
            num("pdop", "PDOP", 16, 0.01, true, ""),
            num(
                "geoidalSeparation",
                "Geoidal Separation",
                32,
                0.01,
                true,
                "m",
            ),
            num("referenceStations", "Reference Stations", 8, 1.0, false, ""),
            look("referenceStationType", "Reference Station Type", 4, &l.gns),
            num(
                "referenceStationId",
                "Reference Station ID",
                12,
                1.0,
                false,
                "",
            ),
            field(
                "ageOfDgnssCorrections",
                "Age of DGNSS Corrections",
                16,
                Kind::Duration,
                0.01,
                false,
                "s",
            ),
        ],
    );
    // the reference stations, as many as field 15 says
    gnss.repeating.push(Repeating {
        start: 15,
        size: 3,
        count: Some(14),
    });
    db.add(gnss);
    db.add(pgn(
        130306,
        "windData",
        "Wind Data",
        Single,
        Some(8),
        2,
        vec![
            sid(),
            num("windSpeed", "Wind Speed", 16, 0.01, false, "m/s"),
            bearing("windAngle", "Wind Angle"),
            look("reference", "Reference", 3, &l.wind),
            reserved("reserved", 21),
        ],
    ));
    db.add(pgn(
        130312,
        "temperature",
        "Temperature",
        Single,
        Some(8),
        5,
        vec![
            sid(),
            num("instance", "Instance", 8, 1.0, false, ""),
            look("source", "Source", 8, &l.temperature),
            num(
                "actualTemperature",
                "Actual Temperature",
                16,
                0.01,
                false,
                "K",
            ),
            num("setTemperature", "Set Temperature", 16, 0.01, false, "K"),
            reserved("reserved", 8),
        ],
    ));
    db.add(pgn(
        130316,
        "temperatureExtendedRange",
        "Temperature Extended Range",
        Single,
        Some(8),
        5,
        vec![
            sid(),
            num("instance", "Instance", 8, 1.0, false, ""),
            look("source", "Source", 8, &l.temperature),
            num("temperature", "Temperature", 24, 0.001, false, "K"),
            num("setTemperature", "Set Temperature", 16, 0.1, false, "K"),
        ],
    ));
    db
}

/// The PGN numbers of the built-in set.
pub const PGNS: [u32; 16] = [
    60928, 126992, 127250, 127251, 127257, 127488, 127489, 127506, 127508, 128267, 129025, 129026,
    129029, 130306, 130312, 130316,
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::n2k::pgn::kept_codes;
    use seabus_medium::{DataMap, Value};
    use std::path::Path;

    /// The datamap of `data` for `pgn`, which must not be short.
    fn decode(pgn: u32, data: &[u8]) -> DataMap {
        let db = database();
        let def = db.select(pgn, data).expect("a built-in PGN");
        let d = def.decode(data);
        assert!(!d.short, "{pgn}: {data:02x?} is short");
        d.map
    }

    #[track_caller]
    fn near(m: &DataMap, key: &str, want: f64, tol: f64) {
        let got = m
            .get_f64(key)
            .unwrap_or_else(|| panic!("no {key} in {m:?}"));
        assert!((got - want).abs() <= tol, "{key}: {got}, not {want}");
    }

    fn keys(m: &DataMap) -> Vec<&str> {
        m.iter().map(|(k, _)| k).collect()
    }

    #[test]
    fn navigation_pgns_decode_from_frames_made_by_hand() {
        // heading 1.5708 rad, deviation −0.01 rad, variation 0.05 rad, magnetic
        let m = decode(127250, &[0x07, 0x5C, 0x3D, 0x9C, 0xFF, 0xF4, 0x01, 0xFD]);
        assert_eq!(
            keys(&m),
            ["sid", "heading", "deviation", "variation", "reference"]
        );
        assert_eq!(m.get_i64("sid"), Some(7));
        near(&m, "heading", (15708.0 * 1e-4f64).to_degrees(), 1e-9);
        near(&m, "deviation", -0.01f64.to_degrees(), 1e-9);
        near(&m, "variation", 0.05f64.to_degrees(), 1e-9);
        assert_eq!(m.get_str("reference"), Some("Magnetic"));
        // rate 0.01 rad/s = 320000 × 3.125e-8
        let m = decode(127251, &[0x01, 0x00, 0xE2, 0x04, 0x00, 0xFF, 0xFF, 0xFF]);
        near(&m, "rate", 0.01f64.to_degrees(), 1e-12);
        // yaw not available, pitch 0.0873 rad, roll −0.1745 rad
        let m = decode(127257, &[0x02, 0xFF, 0x7F, 0x69, 0x03, 0x2F, 0xF9, 0xFF]);
        assert_eq!(
            keys(&m),
            ["sid", "pitch", "roll"],
            "no yaw: it is not available"
        );
        near(&m, "pitch", 0.0873f64.to_degrees(), 1e-9);
        near(&m, "roll", -0.1745f64.to_degrees(), 1e-9);
        // depth 12.34 m, offset 0.5 m, range 100 m
        let m = decode(128267, &[0x05, 0xD2, 0x04, 0x00, 0x00, 0xF4, 0x01, 0x0A]);
        near(&m, "depth", 12.34, 1e-9);
        near(&m, "offset", 0.5, 1e-9);
        assert_eq!(m.get("range"), Some(&Value::Int(100)));
        // 43.5123456° N, 16.44° E
        let m = decode(129025, &[0x00, 0x75, 0xEF, 0x19, 0x80, 0x8B, 0xCC, 0x09]);
        near(&m, "latitude", 43.512_345_6, 1e-12);
        near(&m, "longitude", 16.44, 1e-12);
        // COG 1 rad true, SOG 5.14 m/s
        let m = decode(129026, &[0x06, 0xFC, 0x10, 0x27, 0x02, 0x02, 0xFF, 0xFF]);
        assert_eq!(m.get_str("cogReference"), Some("True"));
        near(&m, "cog", 1f64.to_degrees(), 1e-9);
        near(&m, "sog", 5.14, 1e-9);
        // wind 7.5 m/s at 0.7854 rad, apparent
        let m = decode(130306, &[0x08, 0xEE, 0x02, 0xAE, 0x1E, 0xFA, 0xFF, 0xFF]);
        near(&m, "windSpeed", 7.5, 1e-9);
        near(&m, "windAngle", (7854.0 * 1e-4f64).to_degrees(), 1e-9);
        assert_eq!(m.get_str("reference"), Some("Apparent"));
    }

    #[test]
    fn the_gnss_fix_decodes_with_its_reference_stations() {
        let data = [
            0x09, 0x38, 0x4A, 0x88, 0x3D, 0x75, 0x15, 0x00, 0x80, 0x4B, 0xFD, 0x31, 0x6E, 0x09,
            0x06, 0x00, 0xC0, 0xFF, 0x67, 0x1C, 0xAF, 0xBE, 0xFD, 0x20, 0xBC, 0xBE, 0x00, 0x00,
            0x00, 0x00, 0x00, 0x42, 0xFD, 0x0C, 0x50, 0x00, 0x96, 0x00, 0xA0, 0x0F, 0x00, 0x00,
            0x01, 0x40, 0x06, 0xFA, 0x00,
        ];
        let m = decode(129029, &data);
        assert_eq!(m.get_i64("date"), Some(19000));
        near(&m, "time", 36000.5, 1e-9);
        near(&m, "latitude", 43.5, 1e-12);
        near(&m, "longitude", -16.25, 1e-12);
        near(&m, "altitude", 12.5, 1e-9);
        assert_eq!(m.get_str("gnssType"), Some("GPS+GLONASS"));
        assert_eq!(m.get_str("method"), Some("RTK Fixed Integer"));
        assert_eq!(m.get_str("integrity"), Some("Safe"));
        assert_eq!(m.get_i64("numberOfSvs"), Some(12));
        near(&m, "hdop", 0.8, 1e-9);
        near(&m, "pdop", 1.5, 1e-9);
        near(&m, "geoidalSeparation", 40.0, 1e-9);
        assert_eq!(m.get_i64("referenceStations"), Some(1));
        let list = m
            .get("list")
            .and_then(Value::as_list)
            .expect("the stations");
        assert_eq!(list.len(), 1);
        let s = list[0].as_map().unwrap();
        assert_eq!(s.get_str("referenceStationType"), Some("GPS"));
        assert_eq!(s.get_i64("referenceStationId"), Some(100));
        near(s, "ageOfDgnssCorrections", 2.5, 1e-9);
        // without stations (43 bytes) the list is empty, and nothing is short
        let mut none = data[..43].to_vec();
        none[42] = 0;
        let m = decode(129029, &none);
        assert_eq!(m.get("list"), Some(&Value::List(vec![])));
        // a count of stations the data does not hold is short
        let d = database();
        let def = &d.definitions(129029)[0];
        let mut two = data.to_vec();
        two[42] = 2;
        assert!(def.decode(&two).short);
    }

    #[test]
    fn engine_battery_time_temperature_and_address_claim_decode() {
        // 1500 rpm, boost 120000 Pa, trim −5 %
        let m = decode(127488, &[0x01, 0x70, 0x17, 0xB0, 0x04, 0xFB, 0xFF, 0xFF]);
        assert_eq!(m.get_str("instance"), Some("Dual Engine Starboard"));
        assert_eq!(m.get("speed"), Some(&Value::Float(1500.0)));
        assert_eq!(m.get("boostPressure"), Some(&Value::Int(120_000)));
        assert_eq!(m.get("tiltTrim"), Some(&Value::Int(-5)));
        let m = decode(
            127489,
            &[
                0x00, 0xAC, 0x0D, 0x30, 0x0E, 0xF3, 0x89, 0x8C, 0x05, 0x7D, 0x00, 0x80, 0xEE, 0x36,
                0x00, 0xFF, 0xFF, 0x2C, 0x01, 0xFF, 0x03, 0x00, 0x00, 0x00, 0x32, 0x7F,
            ],
        );
        assert_eq!(
            m.get_str("instance"),
            Some("Single Engine or Dual Engine Port")
        );
        assert_eq!(m.get("oilPressure"), Some(&Value::Int(350_000)));
        near(&m, "oilTemperature", 363.2 - 273.15, 1e-9);
        near(&m, "temperature", 80.0, 1e-9);
        near(&m, "alternatorPotential", 14.2, 1e-9);
        near(&m, "fuelRate", 12.5, 1e-9);
        assert_eq!(m.get("totalEngineHours"), Some(&Value::Int(3_600_000)));
        assert_eq!(m.get("coolantPressure"), None, "not available");
        assert_eq!(m.get("fuelPressure"), Some(&Value::Int(300_000)));
        assert_eq!(
            m.get("discreteStatus1"),
            Some(&Value::List(vec![
                Value::label("Check Engine"),
                Value::label("Over Temperature")
            ]))
        );
        assert_eq!(m.get("discreteStatus2"), Some(&Value::List(vec![])));
        assert_eq!(m.get("engineLoad"), Some(&Value::Int(50)));
        assert_eq!(m.get("engineTorque"), None, "not available");
        // 87 % charged, 95 % healthy, 120 min left, 25 mV ripple, 100 Ah
        let m = decode(
            127506,
            &[
                0x03, 0x00, 0x00, 0x57, 0x5F, 0x78, 0x00, 0x19, 0x00, 0x64, 0x00,
            ],
        );
        assert_eq!(m.get_str("dcType"), Some("Battery"));
        assert_eq!(m.get("stateOfCharge"), Some(&Value::Int(87)));
        assert_eq!(m.get("stateOfHealth"), Some(&Value::Int(95)));
        assert_eq!(m.get("timeRemaining"), Some(&Value::Int(7200)));
        near(&m, "rippleVoltage", 0.025, 1e-12);
        assert_eq!(m.get("remainingCapacity"), Some(&Value::Int(360_000)));
        // 12.8 V, −3.5 A, 25 °C
        let m = decode(127508, &[0x00, 0x00, 0x05, 0xDD, 0xFF, 0x77, 0x74, 0x04]);
        near(&m, "voltage", 12.8, 1e-9);
        near(&m, "current", -3.5, 1e-9);
        near(&m, "temperature", 25.0, 1e-9);
        assert_eq!(m.get_i64("sid"), Some(4));
        // 19000 days and 12:00:00
        let m = decode(126992, &[0x00, 0xF0, 0x38, 0x4A, 0x00, 0xCC, 0xBF, 0x19]);
        assert_eq!(m.get_str("source"), Some("GPS"));
        assert_eq!(m.get_i64("date"), Some(19000));
        near(&m, "time", 43200.0, 1e-9);
        // sea temperature 15 °C, no set temperature
        let m = decode(130312, &[0x01, 0x02, 0x00, 0x8F, 0x70, 0xFF, 0xFF, 0xFF]);
        assert_eq!(m.get_str("source"), Some("Sea Temperature"));
        near(&m, "actualTemperature", 15.0, 1e-9);
        assert_eq!(m.get("setTemperature"), None);
        let m = decode(130316, &[0x01, 0x00, 0x01, 0x0E, 0x52, 0x04, 0xFF, 0xFF]);
        assert_eq!(m.get_str("source"), Some("Outside Temperature"));
        near(&m, "temperature", 10.0, 1e-9);
        // unique number 123456 of an Airmar bottom-depth sensor, marine, arbitrary address
        let m = decode(60928, &[0x40, 0xE2, 0xE1, 0x10, 0x00, 0x82, 0x78, 0xC0]);
        assert_eq!(m.get_i64("uniqueNumber"), Some(123_456));
        assert_eq!(m.get_str("manufacturerCode"), Some("Airmar"));
        assert_eq!(m.get_str("deviceFunction"), Some("Bottom Depth"));
        assert_eq!(m.get_str("deviceClass"), Some("Navigation"));
        assert_eq!(m.get_str("industryGroup"), Some("Marine"));
        assert_eq!(m.get_str("arbitraryAddressCapable"), Some("Yes"));
        // an unnamed lookup value is its number
        let m = decode(60928, &[0x40, 0xE2, 0x01, 0x00, 0x00, 0x82, 0x78, 0xC0]);
        assert_eq!(m.get("manufacturerCode"), Some(&Value::Int(0)));
    }

    /// Writes `raw` as `bits` bits from bit `at` of `data`, least significant first.
    fn put(data: &mut [u8], at: u32, bits: u32, raw: u64) {
        for k in 0..bits {
            let (byte, bit) = (((at + k) / 8) as usize, (at + k) % 8);
            if (raw >> k) & 1 == 1 {
                data[byte] |= 1 << bit;
            } else {
                data[byte] &= !(1 << bit);
            }
        }
    }

    #[test]
    fn every_field_saying_not_available_is_absent() {
        let db = database();
        for pgn in PGNS {
            let def = &db.definitions(pgn)[0];
            // each field set to "not available": all ones, the largest positive value when signed
            for code_below in [0u64, 1, 2] {
                let mut data = vec![0xFF; def.length.unwrap_or(43)];
                for f in &def.fields {
                    let (Some(at), Some(bits)) = (f.bit_offset, f.bits) else {
                        continue;
                    };
                    if bits <= 64
                        && (at + bits) as usize <= 8 * data.len()
                        && kept_codes(bits) > code_below
                    {
                        let top = if f.signed {
                            (1u64 << (bits - 1)) - 1
                        } else {
                            u64::MAX >> (64 - bits)
                        };
                        put(&mut data, at, bits, top - code_below);
                    }
                }
                let m = def.decode(&data).map;
                for (k, v) in m.iter() {
                    // 1-bit fields have no code to spare; bit fields are bits; a named value is
                    // a name; a reference station count of none is an empty list
                    let allowed = matches!(v, Value::List(_) | Value::Str(_));
                    assert!(allowed, "{pgn}: {k} = {v} from code max−{code_below}");
                }
            }
        }
    }

    /// The built-in set against canboat's database (`SEABUS_CANBOAT_JSON`, which the test script
    /// installs): every built-in PGN has the database's identifier, description, type, length,
    /// and fields in the same order with the same identifiers, names, bit offsets and lengths,
    /// resolutions, offsets, signedness, units, types and ranges, and every enumeration value
    /// the set names, the database names the same.
    #[test]
    fn the_built_in_set_matches_canboats_database() {
        let Some(path) = std::env::var_os("SEABUS_CANBOAT_JSON") else {
            eprintln!(
                "SKIPPED the_built_in_set_matches_canboats_database: SEABUS_CANBOAT_JSON is not set \
                 (scripts/test installs canboat's database and sets it)"
            );
            return;
        };
        let theirs = crate::n2k::json::load(Path::new(&path)).unwrap_or_else(|e| panic!("{e}"));
        assert!(theirs.len() > 100, "{} PGNs in {path:?}", theirs.len());
        let ours = database();
        assert_eq!(ours.len(), PGNS.len());
        for pgn in PGNS {
            let mine = &ours.definitions(pgn)[0];
            let defs = theirs.definitions(pgn);
            let db = defs
                .iter()
                .find(|d| !d.fallback)
                .unwrap_or_else(|| panic!("PGN {pgn} is not in the database"));
            let what = format!("PGN {pgn} {}", mine.id);
            assert_eq!(mine.id, db.id, "{what}");
            assert_eq!(mine.description, db.description, "{what}");
            assert_eq!(mine.packet, db.packet, "{what}");
            assert_eq!(mine.length, db.length, "{what}");
            assert_eq!(mine.priority, db.priority, "{what}");
            assert_eq!(mine.repeating, db.repeating, "{what}");
            let names = |d: &PgnDef| {
                d.fields
                    .iter()
                    .map(|f| f.id.to_string())
                    .collect::<Vec<_>>()
            };
            assert_eq!(names(mine), names(db), "{what}: the fields");
            for (a, b) in mine.fields.iter().zip(&db.fields) {
                let what = format!("{what}.{}", a.id);
                assert_eq!(a.name, b.name, "{what}");
                assert_eq!(a.bits, b.bits, "{what}: bits");
                assert_eq!(a.bit_offset, b.bit_offset, "{what}: bit offset");
                assert!(
                    (a.resolution - b.resolution).abs() <= 1e-12 * b.resolution.abs(),
                    "{what}: resolution {} against {}",
                    a.resolution,
                    b.resolution
                );
                assert_eq!(a.offset, b.offset, "{what}: offset");
                let numeric = !matches!(
                    a.kind,
                    Kind::Reserved | Kind::Spare | Kind::Lookup(_) | Kind::BitLookup(_)
                );
                if numeric {
                    assert_eq!(a.signed, b.signed, "{what}: signedness");
                }
                assert_eq!(a.unit, b.unit, "{what}: unit");
                assert_eq!(a.kind.name(), b.kind.name(), "{what}: type");
                if let (Some((lo, hi)), Some((dlo, dhi))) = (a.effective_range(), b.range) {
                    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * y.abs().max(1.0);
                    assert!(
                        close(lo, dlo) && close(hi, dhi),
                        "{what}: range {lo}…{hi} against {dlo}…{dhi}"
                    );
                }
                match (&a.kind, &b.kind) {
                    (Kind::Lookup(x), Kind::Lookup(y)) => {
                        assert_eq!(x.name, y.name, "{what}");
                        for (v, n) in &x.values {
                            assert_eq!(Some(n), y.values.get(v), "{what}: {} {v}", x.name);
                        }
                    }
                    (Kind::BitLookup(x), Kind::BitLookup(y)) => {
                        assert_eq!(x.name, y.name, "{what}");
                        assert_eq!(x.bits, y.bits, "{what}: {}", x.name);
                    }
                    (
                        Kind::IndirectLookup { lookup: x, by: i },
                        Kind::IndirectLookup { lookup: y, by: j },
                    ) => {
                        assert_eq!((&x.name, i), (&y.name, j), "{what}");
                        for (v, n) in &x.values {
                            assert_eq!(Some(n), y.values.get(v), "{what}: {} {v:?}", x.name);
                        }
                    }
                    _ => {}
                }
            }
        }
    }
}
