//! Golden vectors from the RSI spec, both directions, and what must be tolerated or rejected.

use kuka_rsi::{
    ConfigElement, Direction, EthernetConfig, Frame, Ipoc, ParseError, Schema, ValueType,
};

/// The spec's example `<Rob>` (compact, as a KRC sends it).
const ROB: &str = r#"<Rob Type="KUKA"><RIst X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><RSol X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><AIPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><ASPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><Delay D="0"/><IPOC>123645634563</IPOC></Rob>"#;

/// The spec's example `<Sen>`.
const SEN: &str = r#"<Sen Type="ImFree"><RKorr X="0.0000" Y="0.0000" Z="0.0120" A="0.0000" B="0.0000" C="0.0000"/><Stop>0</Stop><IPOC>123645634563</IPOC></Sen>"#;

/// The spec's example Ethernet config (RKorr spelled out).
const CONFIG: &str = r#"<ROOT>
  <CONFIG><IP_NUMBER>192.168.1.10</IP_NUMBER><PORT>49152</PORT><SENTYPE>ImFree</SENTYPE><ONLYSEND>FALSE</ONLYSEND></CONFIG>
  <SEND><ELEMENTS>
    <ELEMENT TAG="DEF_RIst" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_RSol" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_AIPos" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_ASPos" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_Delay" TYPE="LONG" INDX="INTERNAL"/>
  </ELEMENTS></SEND>
  <RECEIVE><ELEMENTS>
    <ELEMENT TAG="RKorr.X" TYPE="DOUBLE" INDX="1" HOLDON="1"/>
    <ELEMENT TAG="RKorr.Y" TYPE="DOUBLE" INDX="2" HOLDON="1"/>
    <ELEMENT TAG="RKorr.Z" TYPE="DOUBLE" INDX="3" HOLDON="1"/>
    <ELEMENT TAG="RKorr.A" TYPE="DOUBLE" INDX="4" HOLDON="1"/>
    <ELEMENT TAG="RKorr.B" TYPE="DOUBLE" INDX="5" HOLDON="1"/>
    <ELEMENT TAG="RKorr.C" TYPE="DOUBLE" INDX="6" HOLDON="1"/>
    <ELEMENT TAG="Stop" TYPE="BOOL" INDX="7" HOLDON="0"/>
  </ELEMENTS></RECEIVE>
</ROOT>"#;

fn cfg() -> EthernetConfig {
    EthernetConfig::parse(CONFIG).unwrap()
}

fn rob() -> Schema {
    cfg().rob_schema(4).unwrap()
}

fn sen() -> Schema {
    cfg().sen_schema(4).unwrap()
}

fn parse_rob(s: &[u8]) -> Result<Frame, ParseError> {
    let mut f = Frame::new();
    rob().parse(s, &mut f).map(|()| f)
}

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

#[test]
fn config_golden() {
    let c = cfg();
    assert_eq!(c.ip.to_string(), "192.168.1.10");
    assert_eq!(c.port, 49152);
    assert_eq!(c.sentype, "ImFree");
    assert!(!c.onlysend);
    assert_eq!(c.send.len(), 5);
    assert_eq!(
        c.receive[6],
        ConfigElement::channel("Stop", ValueType::Bool, 7, Some(false))
    );
    assert_eq!(
        c,
        EthernetConfig::forcecell("192.168.1.10".parse().unwrap(), 49152, false),
        "the spec's file is the one forcecell generates"
    );
    assert_eq!(
        EthernetConfig::parse(&c.to_xml()).unwrap(),
        c,
        "to_xml round-trips"
    );
}

#[test]
fn rob_golden_compact() {
    let f = parse_rob(ROB.as_bytes()).unwrap();
    let s = rob();
    assert_eq!(
        f.get6(s.six("RIst", POSE).unwrap()),
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0]
    );
    assert_eq!(
        f.get6(
            s.six("AIPos", ["A1", "A2", "A3", "A4", "A5", "A6"])
                .unwrap()
        ),
        [0.0, -90.0, 90.0, 0.0, 90.0, 0.0]
    );
    assert_eq!(f.get(s.slot("Delay", "D").unwrap()), 0.0);
    assert_eq!(f.ipoc().value(), 123_645_634_563);
    assert_eq!(f.ipoc().digits(), b"123645634563");
}

#[test]
fn rob_golden_write_is_byte_exact() {
    let s = rob();
    let mut f = Frame::new();
    f.set6(
        s.six("RIst", POSE).unwrap(),
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    f.set6(
        s.six("RSol", POSE).unwrap(),
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    let axes = [0.0, -90.0, 90.0, 0.0, 90.0, 0.0];
    f.set6(
        s.six("AIPos", ["A1", "A2", "A3", "A4", "A5", "A6"])
            .unwrap(),
        axes,
    );
    f.set6(
        s.six("ASPos", ["A1", "A2", "A3", "A4", "A5", "A6"])
            .unwrap(),
        axes,
    );
    f.set(s.slot("Delay", "D").unwrap(), 0.0);
    f.set_ipoc(Ipoc::new(123_645_634_563));
    let mut buf = [0u8; 1024];
    let n = s.write(&f, &mut buf).unwrap();
    assert_eq!(core::str::from_utf8(&buf[..n]).unwrap(), ROB);
}

#[test]
fn sen_golden_both_ways() {
    let s = sen();
    let mut f = Frame::new();
    s.parse(SEN.as_bytes(), &mut f).unwrap();
    assert_eq!(
        f.get6(s.six("RKorr", POSE).unwrap()),
        [0.0, 0.0, 0.012, 0.0, 0.0, 0.0]
    );
    assert_eq!(f.get(s.slot("Stop", "").unwrap()), 0.0);
    let mut buf = [0u8; 512];
    let n = s.write(&f, &mut buf).unwrap();
    assert_eq!(core::str::from_utf8(&buf[..n]).unwrap(), SEN);
}

#[test]
fn pretty_printed_crlf_reordered_and_declared_rob_parse_the_same() {
    let golden = parse_rob(ROB.as_bytes()).unwrap();
    let pretty = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\r\n<Rob TYPE=\"KUKA\">\r\n  \
        <RIst C=\"180.0000\" B=\"0.0000\" A=\"180.0000\" Z=\"890.0000\" Y=\"0.0000\" X=\"445.0000\" />\r\n  \
        <RSol X = '445.0000' Y='0.0000' Z='890.0000' A='180.0000' B='0.0000' C='180.0000'/>\r\n\t\
        <AIPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"></AIPos>\n\
        <ASPos A6=\"0.0000\" A5=\"90.0000\" A4=\"0.0000\" A3=\"90.0000\" A2=\"-90.0000\" A1=\"0.0000\"/>\n\
        <IPOC> 123645634563 </IPOC>\n<Delay D=\"0\" />\n</Rob >\r\n";
    let f = parse_rob(pretty.as_bytes()).unwrap();
    assert_eq!(f, golden);
}

#[test]
fn unknown_elements_and_attributes_are_ignored() {
    let extra = ROB.replace(
        "<Delay D=\"0\"/>",
        "<Delay D=\"0\" Q=\"x\"/><Tech C11=\"1\"/><Foo>bar</Foo>",
    );
    assert_eq!(
        parse_rob(extra.as_bytes()).unwrap(),
        parse_rob(ROB.as_bytes()).unwrap()
    );
}

#[test]
fn rejects_what_the_spec_says_to_reject() {
    type Check = fn(&ParseError) -> bool;
    let cases: Vec<(String, Check)> = vec![
        (String::new(), |e| *e == ParseError::Empty),
        (format!("<!DOCTYPE Rob []>{ROB}"), |e| {
            matches!(e, ParseError::Markup { .. })
        }),
        (
            ROB.replace("<Delay D=\"0\"/>", "<Delay D=\"&amp;\"/>"),
            |e| matches!(e, ParseError::Entity { .. }),
        ),
        (
            ROB.replace("<Delay D=\"0\"/>", "<Delay><![CDATA[0]]></Delay>"),
            |e| matches!(e, ParseError::Markup { .. }),
        ),
        (
            ROB.replace("<Delay D=\"0\"/>", "<Delay><D>0</D></Delay>"),
            |e| matches!(e, ParseError::TooDeep { .. }),
        ),
        (
            ROB.replace("<Delay D=\"0\"/>", "<Delay D=\"0\" D=\"1\"/>"),
            |e| matches!(e, ParseError::DuplicateAttribute { .. }),
        ),
        (ROB.replace("X=\"445.0000\"", "X=\"445.0000\u{e9}\""), |e| {
            matches!(e, ParseError::NonAscii { .. })
        }),
        (ROB.replacen("X=\"445.0000\"", "X=\"\"", 1), |e| {
            matches!(e, ParseError::BadNumber { .. })
        }),
        (ROB.replacen("X=\"445.0000\"", "X=\"NaN\"", 1), |e| {
            matches!(e, ParseError::BadNumber { .. })
        }),
        (ROB.replacen("X=\"445.0000\"", "X=\"inf\"", 1), |e| {
            matches!(e, ParseError::BadNumber { .. })
        }),
        (ROB.replacen("X=\"445.0000\"", "X=\"4.45e2\"", 1), |e| {
            matches!(e, ParseError::BadNumber { .. })
        }),
        (ROB.replace("<IPOC>123645634563</IPOC>", ""), |e| {
            *e == ParseError::MissingIpoc
        }),
        (ROB.replace("123645634563", "12x"), |e| {
            *e == ParseError::BadIpoc
        }),
        (ROB.replace("123645634563", ""), |e| {
            *e == ParseError::BadIpoc
        }),
        (ROB.replace("<Delay D=\"0\"/>", ""), |e| {
            *e == ParseError::MissingElement { element: 4 }
        }),
        (
            ROB.replace("<Delay D=\"0\"/>", "<Delay D=\"0\"/><Delay D=\"0\"/>"),
            |e| *e == ParseError::DuplicateElement { element: 4 },
        ),
        (ROB[..ROB.len() - 3].to_owned(), |e| {
            *e == ParseError::Truncated
        }),
        (ROB[..200].to_owned(), |e| *e == ParseError::Truncated),
        (format!("{ROB}<Rob/>"), |e| {
            matches!(e, ParseError::Syntax { .. })
        }),
        (SEN.to_owned(), |e| *e == ParseError::WrongRoot),
        (ROB.replace("<RIst X", "<RIst\u{1}X"), |e| {
            matches!(e, ParseError::NonAscii { .. })
        }),
    ];
    for (input, ok) in cases {
        match parse_rob(input.as_bytes()) {
            Err(e) => assert!(ok(&e), "{input:?}: unexpected error {e:?}"),
            Ok(_) => panic!("accepted {input:?}"),
        }
    }
}

#[test]
fn sen_with_the_wrong_sentype_or_no_type_is_rejected() {
    let s = sen();
    let mut f = Frame::new();
    let wrong = SEN.replace("ImFree", "Other");
    assert_eq!(
        s.parse(wrong.as_bytes(), &mut f),
        Err(ParseError::WrongType)
    );
    let none = SEN.replace(" Type=\"ImFree\"", "");
    assert_eq!(s.parse(none.as_bytes(), &mut f), Err(ParseError::WrongType));
}

#[test]
fn ipoc_is_echoed_verbatim_and_above_2_pow_32() {
    let input = ROB.replace("123645634563", "0018446744073709551615");
    assert_eq!(
        parse_rob(input.as_bytes()),
        Err(ParseError::BadIpoc),
        "22 digits"
    );
    let input = ROB.replace("123645634563", "00004294967297");
    let f = parse_rob(input.as_bytes()).unwrap();
    assert_eq!(f.ipoc().value(), 4_294_967_297);
    let s = sen();
    let mut out = Frame::new();
    out.set_ipoc(*f.ipoc());
    let mut buf = [0u8; 512];
    let n = s.write(&out, &mut buf).unwrap();
    let text = core::str::from_utf8(&buf[..n]).unwrap();
    assert!(
        text.ends_with("<IPOC>00004294967297</IPOC></Sen>"),
        "{text}"
    );
}

#[test]
fn writer_never_emits_exponent_nan_or_inf() {
    let s = sen();
    let z = s.slot("RKorr", "Z").unwrap();
    let mut f = Frame::new();
    let mut buf = [0u8; 512];
    f.set(z, f64::NAN);
    assert!(s.write(&f, &mut buf).is_err());
    f.set(z, f64::INFINITY);
    assert!(s.write(&f, &mut buf).is_err());
    f.set(z, 1e300);
    assert!(s.write(&f, &mut buf).is_err());
    for v in [1e-12, -3.5e-7, 123456.789_012_3, 1e10] {
        f.set(z, v);
        let n = s.write(&f, &mut buf).unwrap();
        let text = core::str::from_utf8(&buf[..n]).unwrap();
        let values: Vec<&str> = text
            .split("=\"")
            .skip(2)
            .map(|rest| rest.split('"').next().unwrap())
            .collect();
        assert_eq!(values.len(), 6, "{text}");
        for v in values {
            assert!(
                v.bytes()
                    .all(|b| b.is_ascii_digit() || b == b'.' || b == b'-'),
                "{v:?} is not plain fixed-point in {text}"
            );
        }
    }
    assert!(
        s.write(&f, &mut [0u8; 20]).is_err(),
        "a short buffer is an error, not a panic"
    );
}

#[test]
fn config_driven_user_channels_and_text_elements() {
    let mut c = cfg();
    c.send.push(ConfigElement::channel(
        "Force.Fz",
        ValueType::Double,
        1,
        None,
    ));
    c.send
        .push(ConfigElement::channel("Mode", ValueType::Long, 2, None));
    let s = c.rob_schema(3).unwrap();
    let mut f = Frame::new();
    let input = ROB.replace("<IPOC>", "<Force Fz=\"-12.5\"/><Mode>3</Mode><IPOC>");
    s.parse(input.as_bytes(), &mut f).unwrap();
    assert_eq!(f.get(s.slot("Force", "Fz").unwrap()), -12.5);
    assert_eq!(f.get(s.slot("Mode", "").unwrap()), 3.0);
    let missing = ROB.replace("<IPOC>", "<Force Fz=\"-12.5\"/><IPOC>");
    assert!(matches!(
        s.parse(missing.as_bytes(), &mut f),
        Err(ParseError::MissingElement { .. })
    ));
}

#[test]
fn bad_configs_are_refused_with_a_reason() {
    let dup = CONFIG.replace("INDX=\"7\"", "INDX=\"6\"");
    assert!(
        EthernetConfig::parse(&dup)
            .unwrap_err()
            .0
            .contains("INDX 6")
    );
    let unknown = CONFIG.replace("DEF_Delay", "DEF_Bogus");
    assert!(
        EthernetConfig::parse(&unknown)
            .unwrap_err()
            .0
            .contains("DEF_Bogus")
    );
    let no_port = CONFIG.replace("<PORT>49152</PORT>", "");
    assert!(
        EthernetConfig::parse(&no_port)
            .unwrap_err()
            .0
            .contains("PORT")
    );
    let bad_type = CONFIG.replace("TYPE=\"BOOL\"", "TYPE=\"FLOAT\"");
    assert!(
        EthernetConfig::parse(&bad_type)
            .unwrap_err()
            .0
            .contains("FLOAT")
    );
    let unclosed = CONFIG.replace("</ROOT>", "");
    assert!(EthernetConfig::parse(unclosed.as_str()).is_err());
    let commented = format!(
        "<?xml version=\"1.0\"?>\n<!-- robot cell 3 -->\n{}",
        CONFIG.replace("<SEND>", "<!-- what the robot sends --><SEND>")
    );
    assert_eq!(EthernetConfig::parse(&commented).unwrap(), cfg());
    assert!(Schema::new(Direction::Sen, "bad type", 4).is_err());
}

/// The process contract's example `<Rob>`: the spec's message with `FcCmd` before `IPOC`.
const ROB_PROCESS: &str = r#"<Rob Type="KUKA"><RIst X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><RSol X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><AIPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><ASPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><Delay D="0"/><FcCmd Mode="1" F="20.00" Ramp="0.50" Seg="3"/><IPOC>123645634563</IPOC></Rob>"#;

/// The process contract's example `<Sen>` (the spec's reply with `FcState`).
const SEN_PROCESS: &str = r#"<Sen Type="ImFree"><RKorr X="0.0000" Y="0.0000" Z="0.0120" A="0.0000" B="0.0000" C="0.0000"/><Stop>0</Stop><FcState State="3" F="19.98" Fault="0"/><IPOC>123645634563</IPOC></Sen>"#;

fn process_cfg() -> EthernetConfig {
    cfg().with_process(kuka_rsi::ProcessChannels::default())
}

#[test]
fn process_channels_golden_both_ways() {
    use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};
    use kuka_rsi::{CommandSlots, StateSlots};
    let c = process_cfg();
    // The config text round-trips with the new elements.
    let xml = c.to_xml();
    assert!(
        xml.contains(r#"<ELEMENT TAG="FcCmd.Mode" TYPE="LONG" INDX="1" />"#),
        "{xml}"
    );
    assert!(
        xml.contains(r#"<ELEMENT TAG="FcState.F" TYPE="DOUBLE" INDX="9" HOLDON="1" />"#),
        "{xml}"
    );
    assert_eq!(EthernetConfig::parse(&xml).unwrap(), c);

    // <Rob> with FcCmd: parsed into SI, and written back byte for byte at precision 2 for FcCmd.
    let rob = c.rob_schema(4).unwrap();
    let cmd = CommandSlots::find(&rob).unwrap().unwrap();
    let mut f = Frame::new();
    rob.parse(ROB_PROCESS.as_bytes(), &mut f).unwrap();
    assert_eq!(
        cmd.decode(&f),
        ProcessCommand {
            mode: ProcessMode::Press,
            force: 20.0,
            ramp: 0.5,
            segment: 3
        }
    );
    // The robot writes FcCmd with its own precision; the simulated one uses the schema's.
    let mut buf = [0u8; 2048];
    let n = rob.write(&f, &mut buf).unwrap();
    let back = core::str::from_utf8(&buf[..n]).unwrap();
    assert!(
        back.contains(
            r#"<FcCmd Mode="1" F="20.0000" Ramp="0.5000" Seg="3"/><IPOC>123645634563</IPOC>"#
        ),
        "{back}"
    );

    // <Sen> with FcState: byte-exact, F with 2 decimals whatever the schema's precision.
    let mut sen = c.sen_schema(4).unwrap();
    let st = StateSlots::find(&mut sen).unwrap().unwrap();
    let mut f = Frame::new();
    f.set6(
        sen.six("RKorr", POSE).unwrap(),
        [0.0, 0.0, 0.012, 0.0, 0.0, 0.0],
    );
    f.set(sen.slot("Stop", "").unwrap(), 0.0);
    st.encode(
        &ProcessState {
            phase: ProcessPhase::Pressing,
            force: 19.98,
            fault: ProcessFault::None,
        },
        &mut f,
    );
    f.set_ipoc(Ipoc::parse(b"123645634563").unwrap());
    let n = sen.write(&f, &mut buf).unwrap();
    assert_eq!(core::str::from_utf8(&buf[..n]).unwrap(), SEN_PROCESS);
    let mut g = Frame::new();
    sen.parse(SEN_PROCESS.as_bytes(), &mut g).unwrap();
    assert_eq!(st.decode(&g).unwrap().phase, ProcessPhase::Pressing);

    // The config without FcCmd does not need it, and ignores one that arrives.
    let mut plain = Frame::new();
    cfg()
        .rob_schema(4)
        .unwrap()
        .parse(ROB_PROCESS.as_bytes(), &mut plain)
        .unwrap();
    assert_eq!(CommandSlots::find(&cfg().rob_schema(4).unwrap()), Ok(None));
}

#[test]
fn process_values_that_break_the_contract_are_rejected() {
    let rob = process_cfg().rob_schema(4).unwrap();
    let mut f = Frame::new();
    for (good, bad) in [
        (r#"Mode="1""#, r#"Mode="PRESS""#),
        (r#"Mode="1""#, r#"Mode="1.0""#),
        (r#"F="20.00""#, r#"F="inf""#),
        (r#"F="20.00""#, r#"F="2e1""#),
        (r#"Seg="3""#, r#"Seg="99999999999999999999""#),
    ] {
        let msg = ROB_PROCESS.replace(good, bad);
        assert!(
            matches!(
                rob.parse(msg.as_bytes(), &mut f),
                Err(ParseError::BadNumber { .. })
            ),
            "{bad}"
        );
    }
    let msg = ROB_PROCESS.replace(r#" Ramp="0.50""#, "");
    assert!(matches!(
        rob.parse(msg.as_bytes(), &mut f),
        Err(ParseError::MissingElement { .. })
    ));
}
