//! Bad input gives an error that names the file and line — never a panic. Hand-written
//! cases check the error; property tests truncate and mangle valid files at random.

use egoexo_mocap::amc::AmcMotion;
use egoexo_mocap::asf::AsfSkeleton;
use egoexo_mocap::kinematics::{CmuSkeleton, KinematicsError};
use egoexo_mocap::retarget::{RetargetError, Retargeter};
use egoexo_mocap::{CatalogEntry, ImportError, ImportOptions, MotionLibrary, ParseErrorKind, SubjectImporter};
use proptest::prelude::*;

/// A CMU-shaped ASF with the bones the retargeter needs, short directions to keep it small.
fn cmu_like_asf() -> String {
    let bones: [(&str, &str, [f32; 3], f32, &str); 25] = [
        ("lhipjoint", "root", [0.65, -0.71, 0.25], 2.5, ""),
        ("lfemur", "lhipjoint", [0.34, -0.94, 0.0], 7.6, "rx ry rz"),
        ("ltibia", "lfemur", [0.34, -0.94, 0.0], 7.3, "rx"),
        ("lfoot", "ltibia", [0.09, -0.24, 0.97], 2.2, "rx rz"),
        ("ltoes", "lfoot", [0.0, 0.0, 1.0], 1.1, "rx"),
        ("rhipjoint", "root", [-0.65, -0.71, 0.25], 2.5, ""),
        ("rfemur", "rhipjoint", [-0.34, -0.94, 0.0], 7.6, "rx ry rz"),
        ("rtibia", "rfemur", [-0.34, -0.94, 0.0], 7.3, "rx"),
        ("rfoot", "rtibia", [-0.09, -0.24, 0.97], 2.2, "rx rz"),
        ("rtoes", "rfoot", [0.0, 0.0, 1.0], 1.1, "rx"),
        ("lowerback", "root", [0.0, 1.0, -0.05], 2.0, "rx ry rz"),
        ("upperback", "lowerback", [0.0, 1.0, -0.02], 2.0, "rx ry rz"),
        ("thorax", "upperback", [0.0, 1.0, 0.0], 2.0, "rx ry rz"),
        ("lowerneck", "thorax", [0.0, 1.0, 0.1], 1.6, "rx ry rz"),
        ("upperneck", "lowerneck", [0.0, 1.0, -0.06], 1.6, "rx ry rz"),
        ("head", "upperneck", [0.0, 1.0, -0.03], 1.6, "rx ry rz"),
        ("lclavicle", "thorax", [0.97, 0.25, -0.05], 3.6, "ry rz"),
        ("lhumerus", "lclavicle", [1.0, 0.0, 0.0], 4.9, "rx ry rz"),
        ("lradius", "lhumerus", [1.0, 0.0, 0.0], 3.4, "rx"),
        ("lwrist", "lradius", [1.0, 0.0, 0.0], 1.7, "ry"),
        ("lhand", "lwrist", [1.0, 0.0, 0.0], 0.7, "rx rz"),
        ("rclavicle", "thorax", [-0.97, 0.25, -0.05], 3.6, "ry rz"),
        ("rhumerus", "rclavicle", [-1.0, 0.0, 0.0], 4.9, "rx ry rz"),
        ("rradius", "rhumerus", [-1.0, 0.0, 0.0], 3.4, "rx"),
        ("rwrist", "rradius", [-1.0, 0.0, 0.0], 1.7, "ry"),
    ];
    let mut s = String::from(
        "# test skeleton\n:version 1.10\n:name VICON\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n\
         :documentation\n  made for tests\n:root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n\
         \x20  orientation 0 0 0\n:bonedata\n",
    );
    let mut all = bones.to_vec();
    all.push(("rhand", "rwrist", [-1.0, 0.0, 0.0], 0.7, "rx rz"));
    for (i, (name, _, d, len, dof)) in all.iter().enumerate() {
        s += &format!(
            "  begin\n     id {}\n     name {name}\n     direction {} {} {}\n     length {len}\n     axis 0 0 0 XYZ\n",
            i + 1,
            d[0],
            d[1],
            d[2]
        );
        if !dof.is_empty() {
            s += &format!("    dof {dof}\n");
            let limits: Vec<&str> = dof.split(' ').map(|_| "(-180.0 180.0)").collect();
            s += &format!("    limits {}\n", limits.join("\n           "));
        }
        s += "  end\n";
    }
    s += ":hierarchy\n  begin\n";
    let mut parents: Vec<&str> = all.iter().map(|b| b.1).collect();
    parents.dedup();
    let mut seen = Vec::new();
    for p in parents {
        if seen.contains(&p) {
            continue;
        }
        seen.push(p);
        let children: Vec<&str> = all.iter().filter(|b| b.1 == p).map(|b| b.0).collect();
        s += &format!("    {p} {}\n", children.join(" "));
    }
    s += "  end\n";
    s
}

fn cmu_like_amc(asf: &AsfSkeleton, frames: usize) -> String {
    let mut s = String::from("#!OML:ASF test.asf\n:FULLY-SPECIFIED\n:DEGREES\n");
    for f in 0..frames {
        s += &format!("{}\nroot {} 16.5 {} 1.5 {} -2.0\n", f + 1, 0.1 * f as f32, 0.3 * f as f32, f as f32);
        for bone in &asf.bones {
            if bone.dofs.is_empty() {
                continue;
            }
            let values: Vec<String> = (0..bone.dofs.len()).map(|k| format!("{}", (f + k) as f32 * 0.5)).collect();
            s += &format!("{} {}\n", bone.name, values.join(" "));
        }
    }
    s
}

fn entry() -> CatalogEntry {
    CatalogEntry { description: "test".to_owned(), framerate: 120.0 }
}

#[test]
fn the_synthetic_files_are_valid_and_import() {
    let asf_text = cmu_like_asf();
    let importer = SubjectImporter::new(1, &asf_text, "01.asf").unwrap();
    let amc = cmu_like_amc(importer.asf(), 130);
    let import = importer.import_trial(1, &amc, "01_01.amc", &entry(), &ImportOptions::default()).unwrap();
    assert_eq!(import.clips.len(), 1);
    assert_eq!(import.clips[0].poses.len(), 33);
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn amc_errors_name_the_line() {
    let asf = AsfSkeleton::parse(&cmu_like_asf(), "01.asf").unwrap();
    let good = cmu_like_amc(&asf, 3);

    let bad = good.replacen("lradius 1", "lradius nan", 1);
    let err = AmcMotion::parse(&bad, "01_01.amc", &asf).unwrap_err();
    assert_eq!(err.location.line, Some(line_of(&bad, "lradius nan")));
    assert!(matches!(err.kind, ParseErrorKind::BadNumber(_)), "{err}");
    assert!(err.to_string().starts_with("01_01.amc:"), "{err}");

    let bad = good.replacen("\n3\n", "\n5\n", 1);
    let err = AmcMotion::parse(&bad, "01_01.amc", &asf).unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::FrameOutOfSequence { previous: 2, found: 5 }), "{err}");

    let bad = good.replacen("lradius 1", "lradius 1 2", 1);
    let err = AmcMotion::parse(&bad, "01_01.amc", &asf).unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::WrongValueCount { expected: 1, found: 2, .. }), "{err}");

    let bad = good.replacen("lradius", "ltentacle", 1);
    let err = AmcMotion::parse(&bad, "01_01.amc", &asf).unwrap_err();
    assert_eq!(err.kind, ParseErrorKind::UnknownBone("ltentacle".to_owned()));

    let bad = good.replacen("lfemur", "lfemur 0 0 0\nlfemur", 1);
    let err = AmcMotion::parse(&bad, "01_01.amc", &asf).unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::RepeatedBoneInFrame { frame: 1, .. }), "{err}");

    let err = AmcMotion::parse(":FULLY-SPECIFIED\n:DEGREES\n", "empty.amc", &asf).unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::UnexpectedEnd { .. }) && err.location.line.is_none(), "{err}");

    let err = AmcMotion::parse("root 0 0 0 0 0 0\n", "x.amc", &asf).unwrap_err();
    assert_eq!(err.location.line, Some(1));
}

#[test]
fn asf_errors_name_the_line() {
    let good = cmu_like_asf();
    let bad = good.replacen("    lfemur ltibia", "    lfemur lshin", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert_eq!(err.kind, ParseErrorKind::UnknownBone("lshin".to_owned()));
    assert_eq!(err.location.line, Some(line_of(&bad, "lfemur lshin")));

    let bad = good.replacen("    lfemur ltibia\n", "", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert_eq!(err.kind, ParseErrorKind::Unattached("ltibia".to_owned()));

    let bad = good.replacen("    ltibia lfoot\n", "    ltibia lfoot lfemur\n", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::TwoParents { .. }), "{err}");

    let bad = good.replacen("axis 0 0 0 XYZ", "axis 0 0 0 XYX", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::Expected { .. }), "{err}");

    let bad = good.replacen("    limits (-180.0 180.0)\n           (-180.0 180.0)\n", "    limits (-180.0 180.0)\n", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert!(matches!(err.kind, ParseErrorKind::LimitCountMismatch { .. }), "{err}");

    let cut = &good[..good.find(":hierarchy").unwrap()];
    let err = AsfSkeleton::parse(cut, "01.asf").unwrap_err();
    assert_eq!(err.kind, ParseErrorKind::MissingSection(":hierarchy"));

    let bad = good.replacen("  end\n", "", 1);
    let err = AsfSkeleton::parse(&bad, "01.asf").unwrap_err();
    assert!(err.location.line.is_some(), "{err}");

    let bad = good.replacen("length 0.45", "length -1", 1);
    assert!(AsfSkeleton::parse(&bad, "01.asf").is_err());
}

#[test]
fn unsupported_skeletons_are_errors() {
    let good = cmu_like_asf();
    let with_tx = good.replacen("dof rx\n    limits (-180.0 180.0)\n", "dof rx tx\n", 1);
    let asf = AsfSkeleton::parse(&with_tx, "01.asf").unwrap();
    assert!(matches!(CmuSkeleton::from_asf(&asf), Err(KinematicsError::UnsupportedDof { dof: "tx", .. })));

    let renamed = good.replace("lfemur", "lthigh");
    let asf = AsfSkeleton::parse(&renamed, "01.asf").unwrap();
    let skeleton = CmuSkeleton::from_asf(&asf).unwrap();
    assert!(matches!(Retargeter::new(&skeleton), Err(RetargetError::MissingBone { bone: "lfemur", .. })));
    let err = SubjectImporter::new(1, &renamed, "01.asf").unwrap_err();
    assert!(err.to_string().starts_with("01.asf: "), "{err}");
}

#[test]
fn a_trial_that_is_all_glitches_is_an_error() {
    let asf_text = cmu_like_asf();
    let importer = SubjectImporter::new(1, &asf_text, "01.asf").unwrap();
    // The root jumps a metre every frame.
    let mut amc = String::new();
    for f in 0..200 {
        amc += &format!("{}\nroot {} 16 0 0 0 0\n", f + 1, (f % 2) as f32 * 20.0);
        for bone in &importer.asf().bones {
            if !bone.dofs.is_empty() {
                amc += &format!("{} {}\n", bone.name, vec!["0"; bone.dofs.len()].join(" "));
            }
        }
    }
    let err = importer.import_trial(1, &amc, "01_01.amc", &entry(), &ImportOptions::default()).unwrap_err();
    assert!(matches!(err, ImportError::NoCleanFrames { glitches: 199, .. }), "{err}");
}

#[test]
fn library_bytes_that_are_not_a_library_are_errors() {
    assert!(MotionLibrary::from_bytes(Vec::new()).is_err());
    assert!(MotionLibrary::from_bytes(b"not a library at all".to_vec()).is_err());
    let plain = safetensors::serialize(Vec::<(&str, safetensors::tensor::TensorView<'_>)>::new(), None).unwrap();
    assert!(matches!(MotionLibrary::from_bytes(plain), Err(egoexo_mocap::LibraryError::MissingHeader)));
}

fn small_library() -> Vec<u8> {
    let importer = SubjectImporter::new(1, &cmu_like_asf(), "01.asf").unwrap();
    let amc = cmu_like_amc(importer.asf(), 125);
    let import = importer.import_trial(1, &amc, "01_01.amc", &entry(), &ImportOptions::default()).unwrap();
    MotionLibrary::build(30.0, "test", import.clips).unwrap().as_bytes().to_vec()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn truncated_or_mangled_asf_never_panics(cut in 0.0f64..1.0, line in 0usize..400, garbage in prop::sample::select(vec![
        "", "nan", "1e999", "(", ")", "-", "begin", "end", ":root", ":bonedata", "limits (1", "dof rq", "axis 1 2", "root root", "\u{feff}", "é",
    ])) {
        let good = cmu_like_asf();
        let mut at = (good.len() as f64 * cut) as usize;
        while !good.is_char_boundary(at) { at -= 1; }
        let _ = AsfSkeleton::parse(&good[..at], "cut.asf");

        let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
        let n = lines.len();
        let i = line % n;
        lines[i] = garbage.to_owned();
        let mangled = lines.join("\n");
        if let Err(e) = AsfSkeleton::parse(&mangled, "mangled.asf") {
            prop_assert_eq!(&e.location.file, "mangled.asf");
            prop_assert!(e.location.line.is_none_or(|l| l >= 1 && l <= n), "{}", e);
        }
        lines.remove(i);
        if let Ok(asf) = AsfSkeleton::parse(&lines.join("\n"), "short.asf")
            && let Ok(sk) = CmuSkeleton::from_asf(&asf)
        {
            let _ = Retargeter::new(&sk);
        }
    }

    #[test]
    fn truncated_or_mangled_amc_never_panics(cut in 0.0f64..1.0, line in 0usize..2000, garbage in prop::sample::select(vec![
        "", "nan", "inf", "-1e40", "root", "root 1 2 3", "7", "-3", "lfemur 1 2", "lfemur a b c", ":RADIANS", "1 2", "x",
    ])) {
        let importer = SubjectImporter::new(1, &cmu_like_asf(), "01.asf").unwrap();
        let good = cmu_like_amc(importer.asf(), 130);
        let mut at = (good.len() as f64 * cut) as usize;
        while !good.is_char_boundary(at) { at -= 1; }
        let _ = importer.import_trial(1, &good[..at], "cut.amc", &entry(), &ImportOptions::default());

        let mut lines: Vec<&str> = good.lines().collect();
        let n = lines.len();
        lines[line % n] = garbage;
        let mangled = lines.join("\n");
        match importer.import_trial(1, &mangled, "mangled.amc", &entry(), &ImportOptions::default()) {
            Ok(import) => prop_assert!(import.clips.iter().all(|c| c.poses.iter().all(|p| p.is_finite()))),
            Err(ImportError::Parse(e)) => {
                prop_assert_eq!(&e.location.file, "mangled.amc");
                prop_assert!(e.location.line.is_none_or(|l| l >= 1 && l <= n), "{}", e);
            }
            Err(_) => {}
        }
    }

    #[test]
    fn damaged_library_bytes_never_panic(cut in 0.0f64..1.0, flips in prop::collection::vec((0.0f64..1.0, any::<u8>()), 1..8)) {
        let bytes = small_library();
        let _ = MotionLibrary::from_bytes(bytes[..(bytes.len() as f64 * cut) as usize].to_vec());
        let mut damaged = bytes.clone();
        for (at, value) in flips {
            let i = ((damaged.len() - 1) as f64 * at) as usize;
            damaged[i] = value;
        }
        if let Ok(library) = MotionLibrary::from_bytes(damaged) {
            for clip in 0..library.clips().len() {
                let _ = library.motion(clip);
                let _ = library.error_histogram(clip);
            }
            let _ = library.retarget_summary(&(0..library.clips().len() + 1).collect::<Vec<_>>());
        }
    }
}
