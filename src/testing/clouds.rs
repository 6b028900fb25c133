//! Point-cloud files written by the `las` and `e57` crates' own writers (not
//! by the readers under test), for tests and the hostile-files harness.

use std::path::Path;

use glam::{DVec3, Vec3};

/// Writes a LAS (or, for a `.laz` path, LAZ) file: point format 7 (RGB) or,
/// without colours, 6; intensity and classification per point; coordinates
/// to the millimetre; `wkt` as the CRS record where given.
pub fn write_las(path: &Path, positions: &[DVec3], colours: Option<&[Vec3]>, intensity: &[u16], classes: &[u8], wkt: Option<&str>) -> las::Result<()> {
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(if colours.is_some() { 7 } else { 6 })?;
    let lo = positions.iter().fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
    let t = |offset: f64| las::Transform { scale: 0.001, offset: offset.floor() };
    b.transforms = las::Vector { x: t(lo.x), y: t(lo.y), z: t(lo.z) };
    b.generating_software = "shapeshifter tests (las crate)".into();
    if let Some(w) = wkt {
        b.has_wkt_crs = true;
        b.vlrs.push(las::Vlr { user_id: "LASF_Projection".into(), record_id: 2112, description: "OGC WKT".into(), data: w.as_bytes().to_vec() });
    }
    let mut w = las::Writer::from_path(path, b.into_header()?)?;
    for (i, p) in positions.iter().enumerate() {
        let mut q = las::Point { x: p.x, y: p.y, z: p.z, intensity: intensity[i], ..Default::default() };
        q.classification = las::point::Classification::new(classes[i])?;
        q.return_number = 1;
        q.number_of_returns = 1;
        if let Some(c) = colours {
            let c = (c[i].clamp(Vec3::ZERO, Vec3::ONE) * 65535.0).round();
            q.color = Some(las::Color { red: c.x as u16, green: c.y as u16, blue: c.z as u16 });
        }
        q.gps_time = Some(0.0);
        w.write_point(q)?;
    }
    w.close()
}

/// Writes an E57 file of one scan: Cartesian f64 coordinates, RGB (8-bit)
/// where given, intensity in [0, 1].
pub fn write_e57(path: &Path, positions: &[DVec3], colours: Option<&[Vec3]>, intensity: &[f32]) -> e57::Result<()> {
    use e57::{Record, RecordDataType, RecordName, RecordValue};
    let mut w = e57::E57Writer::from_file(path, "shapeshifter-test-file")?;
    let mut proto = vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64];
    if colours.is_some() {
        for name in [RecordName::ColorRed, RecordName::ColorGreen, RecordName::ColorBlue] {
            proto.push(Record { name, data_type: RecordDataType::U8 });
        }
    }
    proto.push(Record { name: RecordName::Intensity, data_type: RecordDataType::UNIT_F32 });
    let mut pc = w.add_pointcloud("shapeshifter-test-scan", proto)?;
    for (i, p) in positions.iter().enumerate() {
        let mut v = vec![RecordValue::Double(p.x), RecordValue::Double(p.y), RecordValue::Double(p.z)];
        if let Some(c) = colours {
            let c = (c[i].clamp(Vec3::ZERO, Vec3::ONE) * 255.0).round();
            v.extend([RecordValue::Integer(c.x as i64), RecordValue::Integer(c.y as i64), RecordValue::Integer(c.z as i64)]);
        }
        v.push(RecordValue::Single(intensity[i]));
        pc.add_point(v)?;
    }
    pc.finalize()?;
    w.finalize()
}
