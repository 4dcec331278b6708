//! A loader for the subset of MJCF that describes a humanoid character: a body tree with sphere,
//! capsule and box geoms, hinge joints (one hinge = a 1-DoF joint; three hinges about x, y, z in
//! one body = a 3-DoF ball joint, as MuJoCo composes them) and `position` actuators carrying the PD
//! gains (`kp`, `kv`) and torque limits (`forcerange`). Anything outside the subset is an error
//! naming the element, not silently ignored: a character must not load differently from what its
//! file says.

use std::path::Path;

/// The shipped character: the AMP humanoid of DESIGN.md §4.
pub const AMP_HUMANOID_XML: &str = include_str!("../assets/amp_humanoid.xml");

#[derive(Debug, thiserror::Error)]
pub enum MjcfError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: not valid XML: {message}")]
    Xml { file: String, message: String },
    #[error("{file}: <{element} name=\"{name}\">: {message}")]
    Element {
        file: String,
        element: String,
        name: String,
        message: String,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub enum GeomShape {
    Sphere {
        radius: f64,
    },
    /// Segment endpoints in the body frame.
    Capsule {
        from: [f64; 3],
        to: [f64; 3],
        radius: f64,
    },
    Box {
        half: [f64; 3],
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct GeomDef {
    pub name: String,
    pub shape: GeomShape,
    /// Centre in the body frame (capsules: the segment's midpoint).
    pub pos: [f64; 3],
    /// kg / m^3
    pub density: f64,
    /// Sliding friction coefficient (the first of MJCF's three `friction` numbers; rapier has no
    /// torsional or rolling friction, so the other two must be MuJoCo's small defaults).
    pub friction: f64,
}

impl GeomDef {
    pub fn volume(&self) -> f64 {
        use std::f64::consts::PI;
        match &self.shape {
            GeomShape::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
            GeomShape::Capsule { from, to, radius } => {
                let len = dist3(*from, *to);
                PI * radius * radius * len + 4.0 / 3.0 * PI * radius.powi(3)
            }
            GeomShape::Box { half } => 8.0 * half[0] * half[1] * half[2],
        }
    }

    pub fn mass(&self) -> f64 {
        self.volume() * self.density
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum JointKind {
    /// The root: six free degrees of freedom, not actuated.
    Free,
    /// Welded to its parent (the hands of the AMP humanoid).
    Fixed,
    /// One actuated hinge; index into [`CharacterModel::dofs`].
    Hinge { dof: usize },
    /// Three actuated hinges about the body's x, y, z axes, composed Rx·Ry·Rz.
    Ball { dofs: [usize; 3] },
}

#[derive(Clone, Debug, PartialEq)]
pub struct BodyDef {
    pub name: String,
    pub parent: Option<usize>,
    /// Origin in the parent's frame (the world's for the root).
    pub pos: [f64; 3],
    pub geoms: Vec<GeomDef>,
    pub joint: JointKind,
}

/// One actuated degree of freedom, in file order (the order of the action vector).
#[derive(Clone, Debug, PartialEq)]
pub struct DofDef {
    pub name: String,
    pub body: usize,
    /// Unit axis in the body frame.
    pub axis: [f64; 3],
    /// [lower, upper] in radians.
    pub range: [f64; 2],
    pub kp: f64,
    pub kd: f64,
    pub torque_limit: f64,
    /// Reflected rotor inertia added to the joint-space mass matrix (MJCF `armature`, kg·m²).
    pub armature: f64,
    /// Passive viscous joint damping (MJCF `damping`, N·m·s/rad).
    pub damping: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CharacterModel {
    pub name: String,
    /// Parents come before their children; body 0 is the root.
    pub bodies: Vec<BodyDef>,
    pub dofs: Vec<DofDef>,
}

impl CharacterModel {
    /// The shipped AMP humanoid.
    pub fn amp_humanoid() -> Self {
        Self::parse(AMP_HUMANOID_XML, "sim/assets/amp_humanoid.xml")
            .expect("the shipped character file is valid (tested)")
    }

    pub fn from_file(path: &Path) -> Result<Self, MjcfError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| MjcfError::Io {
            file: file.clone(),
            source,
        })?;
        Self::parse(&text, &file)
    }

    pub fn total_mass(&self) -> f64 {
        self.bodies
            .iter()
            .flat_map(|b| &b.geoms)
            .map(GeomDef::mass)
            .sum()
    }

    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    pub fn parse(text: &str, file: &str) -> Result<Self, MjcfError> {
        let doc = roxmltree::Document::parse(text).map_err(|e| MjcfError::Xml {
            file: file.into(),
            message: e.to_string(),
        })?;
        let root = doc.root_element();
        let mut p = Parser {
            file,
            degrees: true,
            bodies: Vec::new(),
            dofs: Vec::new(),
            default_density: 1000.0,
            joint_defaults: JointDefaults::default(),
            default_friction: 1.0,
        };
        if root.tag_name().name() != "mujoco" {
            return Err(p.err(root, "the root element must be <mujoco>"));
        }
        for child in root.children().filter(|n| n.is_element()) {
            match child.tag_name().name() {
                "compiler" => {
                    p.degrees = child.attribute("angle").unwrap_or("degree") != "radian";
                }
                "worldbody" => {
                    let bodies: Vec<_> = child
                        .children()
                        .filter(|n| n.has_tag_name("body"))
                        .collect();
                    if bodies.len() != 1 {
                        return Err(p.err(
                            child,
                            "exactly one root <body> (the character) is supported",
                        ));
                    }
                    p.body(bodies[0], None)?;
                }
                "actuator" => {
                    for a in child.children().filter(|n| n.is_element()) {
                        p.actuator(a)?;
                    }
                }
                "default" => p.defaults(child)?,
                // Simulation options, visual settings and assets do not change the character.
                "option" | "visual" | "asset" | "size" | "statistic" | "contact" => {}
                other => return Err(p.err(child, &format!("<{other}> is not supported"))),
            }
        }
        if let Some(d) = p.dofs.iter().find(|d| d.kp <= 0.0 || d.torque_limit <= 0.0) {
            return Err(MjcfError::Element {
                file: file.into(),
                element: "joint".into(),
                name: d.name.clone(),
                message: "no <position> actuator with kp and forcerange drives it".into(),
            });
        }
        let name = root.attribute("model").unwrap_or("character").to_string();
        if p.bodies.is_empty() {
            return Err(p.err(root, "no character body in <worldbody>"));
        }
        Ok(CharacterModel {
            name,
            bodies: p.bodies,
            dofs: p.dofs,
        })
    }
}

struct Parser<'f> {
    file: &'f str,
    degrees: bool,
    bodies: Vec<BodyDef>,
    dofs: Vec<DofDef>,
    default_density: f64,
    joint_defaults: JointDefaults,
    /// MuJoCo's default sliding friction unless `<default><geom friction>` says otherwise.
    default_friction: f64,
}

/// Joint attributes a `<default><joint>` sets for every hinge.
#[derive(Clone, Copy, Debug, Default)]
struct JointDefaults {
    armature: f64,
    damping: f64,
}

/// Attributes each element may carry; any other is an error, so a file never loads differently
/// from what it says.
const JOINT_ATTRS: &[&str] = &[
    "name", "type", "axis", "range", "pos", "armature", "damping", "limited",
];
const DEFAULT_JOINT_ATTRS: &[&str] = &["armature", "damping", "limited"];
const GEOM_ATTRS: &[&str] = &[
    "name",
    "type",
    "size",
    "pos",
    "fromto",
    "density",
    "friction",
    "contype",
    "conaffinity",
    "condim",
    "rgba",
    "material",
    "quat",
    "euler",
];
const DEFAULT_GEOM_ATTRS: &[&str] = &[
    "friction",
    "contype",
    "conaffinity",
    "condim",
    "density",
    "rgba",
];

fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

impl Parser<'_> {
    fn err(&self, node: roxmltree::Node, message: &str) -> MjcfError {
        MjcfError::Element {
            file: self.file.into(),
            element: node.tag_name().name().into(),
            name: node.attribute("name").unwrap_or("").into(),
            message: format!(
                "{message} (line {})",
                node.document().text_pos_at(node.range().start).row
            ),
        }
    }

    /// Refuses attributes outside `allowed`, naming the first one.
    fn check_attrs(&self, node: roxmltree::Node, allowed: &[&str]) -> Result<(), MjcfError> {
        match node.attributes().find(|a| !allowed.contains(&a.name())) {
            Some(a) => Err(self.err(
                node,
                &format!("attribute `{}` is not supported here", a.name()),
            )),
            None => Ok(()),
        }
    }

    /// A non-negative number attribute, or `default` when absent.
    fn non_negative(
        &self,
        node: roxmltree::Node,
        attr: &str,
        default: f64,
    ) -> Result<f64, MjcfError> {
        match self.floats(node, attr)? {
            None => Ok(default),
            Some(v) if v.len() == 1 && v[0] >= 0.0 => Ok(v[0]),
            Some(_) => Err(self.err(node, &format!("`{attr}` must be one number >= 0"))),
        }
    }

    /// Sliding friction from `friction="slide [torsion [rolling]]"`. rapier has only sliding
    /// friction: torsional and rolling coefficients above MuJoCo's defaults (0.005, 0.0001) would
    /// be ignored, so they are refused.
    fn friction(&self, node: roxmltree::Node, default: f64) -> Result<f64, MjcfError> {
        match self.floats(node, "friction")? {
            None => Ok(default),
            Some(v) if !v.is_empty() && v.len() <= 3 && v[0] >= 0.0 => {
                if v.get(1).is_some_and(|t| *t > 0.005 + 1e-12)
                    || v.get(2).is_some_and(|r| *r > 0.0001 + 1e-12)
                {
                    return Err(self.err(
                        node,
                        "torsional or rolling friction above MuJoCo's defaults is not supported",
                    ));
                }
                Ok(v[0])
            }
            Some(_) => Err(self.err(node, "`friction` needs 1 to 3 numbers, the first >= 0")),
        }
    }

    /// `<default>`: joint armature and damping, geom friction (and density) for every element.
    /// Default classes are not supported.
    fn defaults(&mut self, node: roxmltree::Node) -> Result<(), MjcfError> {
        self.check_attrs(node, &[])?;
        for child in node.children().filter(|n| n.is_element()) {
            match child.tag_name().name() {
                "joint" => {
                    self.check_attrs(child, DEFAULT_JOINT_ATTRS)?;
                    self.joint_defaults = JointDefaults {
                        armature: self.non_negative(child, "armature", 0.0)?,
                        damping: self.non_negative(child, "damping", 0.0)?,
                    };
                }
                "geom" => {
                    self.check_attrs(child, DEFAULT_GEOM_ATTRS)?;
                    self.default_friction = self.friction(child, self.default_friction)?;
                    if let Some(d) = self.floats(child, "density")? {
                        match d.as_slice() {
                            [d] if *d > 0.0 => self.default_density = *d,
                            _ => return Err(self.err(child, "density must be one positive number")),
                        }
                    }
                }
                other => {
                    return Err(self.err(
                        child,
                        &format!("<{other}> defaults (and default classes) are not supported"),
                    ))
                }
            }
        }
        Ok(())
    }

    fn floats(&self, node: roxmltree::Node, attr: &str) -> Result<Option<Vec<f64>>, MjcfError> {
        let Some(s) = node.attribute(attr) else {
            return Ok(None);
        };
        s.split_whitespace()
            .map(|x| x.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .map(Some)
            .ok_or_else(|| self.err(node, &format!("`{attr}=\"{s}\"` is not a list of numbers")))
    }

    fn vec3(
        &self,
        node: roxmltree::Node,
        attr: &str,
        default: [f64; 3],
    ) -> Result<[f64; 3], MjcfError> {
        match self.floats(node, attr)? {
            None => Ok(default),
            Some(v) if v.len() == 3 => Ok([v[0], v[1], v[2]]),
            Some(_) => Err(self.err(node, &format!("`{attr}` needs 3 numbers"))),
        }
    }

    fn body(&mut self, node: roxmltree::Node, parent: Option<usize>) -> Result<(), MjcfError> {
        if node.attribute("quat").is_some()
            || node.attribute("euler").is_some()
            || node.attribute("axisangle").is_some()
        {
            return Err(self.err(
                node,
                "rotated body frames are not supported; rotate geoms and axes instead",
            ));
        }
        let index = self.bodies.len();
        let name = node
            .attribute("name")
            .map_or_else(|| format!("body{index}"), str::to_string);
        let pos = self.vec3(node, "pos", [0.0; 3])?;
        let mut geoms = Vec::new();
        let mut hinges: Vec<(String, [f64; 3], [f64; 2], JointDefaults)> = Vec::new();
        let mut free = false;
        for child in node.children().filter(|n| n.is_element()) {
            match child.tag_name().name() {
                "freejoint" => free = true,
                "joint" => match child.attribute("type").unwrap_or("hinge") {
                    "free" => free = true,
                    "hinge" => {
                        self.check_attrs(child, JOINT_ATTRS)?;
                        let passive = JointDefaults {
                            armature: self.non_negative(
                                child,
                                "armature",
                                self.joint_defaults.armature,
                            )?,
                            damping: self.non_negative(
                                child,
                                "damping",
                                self.joint_defaults.damping,
                            )?,
                        };
                        let jname = child
                            .attribute("name")
                            .ok_or_else(|| {
                                self.err(child, "a hinge needs a name (actuators refer to it)")
                            })?
                            .to_string();
                        let axis = self.vec3(child, "axis", [0.0, 0.0, 1.0])?;
                        let norm = dist3(axis, [0.0; 3]);
                        if norm < 1e-9 {
                            return Err(self.err(child, "zero axis"));
                        }
                        let axis = axis.map(|a| a / norm);
                        if self.vec3(child, "pos", [0.0; 3])? != [0.0; 3] {
                            return Err(self.err(child, "hinges must sit at the body origin"));
                        }
                        let range = match self.floats(child, "range")? {
                            Some(r) if r.len() == 2 && r[0] < r[1] => {
                                let k = if self.degrees {
                                    std::f64::consts::PI / 180.0
                                } else {
                                    1.0
                                };
                                [r[0] * k, r[1] * k]
                            }
                            _ => return Err(self.err(child, "needs `range=\"lower upper\"`")),
                        };
                        hinges.push((jname, axis, range, passive));
                    }
                    other => {
                        return Err(
                            self.err(child, &format!("joint type {other:?} is not supported"))
                        )
                    }
                },
                "geom" => geoms.push(self.geom(child)?),
                "body" | "inertial" | "site" | "camera" | "light" => {}
                other => {
                    return Err(
                        self.err(child, &format!("<{other}> inside a body is not supported"))
                    )
                }
            }
        }
        let joint = match (parent, free, hinges.len()) {
            (None, true, 0) => JointKind::Free,
            (None, _, _) => return Err(self.err(node, "the root body needs a <freejoint/> and no hinges")),
            (Some(_), false, 0) => JointKind::Fixed,
            (Some(_), false, 1) => JointKind::Hinge { dof: self.dofs.len() },
            (Some(_), false, 3) => {
                let unit = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
                if hinges.iter().zip(unit).any(|((_, a, _, _), u)| dist3(*a, u) > 1e-9) {
                    return Err(self.err(node, "three hinges must be about x, y, z in that order"));
                }
                let n = self.dofs.len();
                JointKind::Ball { dofs: [n, n + 1, n + 2] }
            }
            (Some(_), _, n) => {
                return Err(self.err(
                    node,
                    &format!("{n} hinges: a body has 1 or 3 (2-DoF multibody joints are not supported by rapier)"),
                ))
            }
        };
        for (jname, axis, range, passive) in hinges {
            self.dofs.push(DofDef {
                name: jname,
                body: index,
                axis,
                range,
                kp: 0.0,
                kd: 0.0,
                torque_limit: 0.0,
                armature: passive.armature,
                damping: passive.damping,
            });
        }
        self.bodies.push(BodyDef {
            name,
            parent,
            pos,
            geoms,
            joint,
        });
        for child in node.children().filter(|n| n.has_tag_name("body")) {
            self.body(child, Some(index))?;
        }
        Ok(())
    }

    fn geom(&self, node: roxmltree::Node) -> Result<GeomDef, MjcfError> {
        self.check_attrs(node, GEOM_ATTRS)?;
        let friction = self.friction(node, self.default_friction)?;
        let name = node.attribute("name").unwrap_or("").to_string();
        let size = self.floats(node, "size")?.unwrap_or_default();
        let density = match self.floats(node, "density")? {
            Some(d) if d.len() == 1 && d[0] > 0.0 => d[0],
            Some(_) => return Err(self.err(node, "density must be one positive number")),
            None => self.default_density,
        };
        let need = |n: usize| -> Result<(), MjcfError> {
            if size.len() < n || size[..n].iter().any(|s| *s <= 0.0) {
                Err(self.err(node, &format!("`size` needs {n} positive numbers")))
            } else {
                Ok(())
            }
        };
        let (shape, pos) = match node.attribute("type").unwrap_or("sphere") {
            "sphere" => {
                need(1)?;
                (
                    GeomShape::Sphere { radius: size[0] },
                    self.vec3(node, "pos", [0.0; 3])?,
                )
            }
            "capsule" => {
                need(1)?;
                let ft = self
                    .floats(node, "fromto")?
                    .filter(|v| v.len() == 6)
                    .ok_or_else(|| self.err(node, "capsules need `fromto` (6 numbers)"))?;
                let (from, to) = ([ft[0], ft[1], ft[2]], [ft[3], ft[4], ft[5]]);
                let mid = [
                    (from[0] + to[0]) / 2.0,
                    (from[1] + to[1]) / 2.0,
                    (from[2] + to[2]) / 2.0,
                ];
                (
                    GeomShape::Capsule {
                        from,
                        to,
                        radius: size[0],
                    },
                    mid,
                )
            }
            "box" => {
                need(3)?;
                (
                    GeomShape::Box {
                        half: [size[0], size[1], size[2]],
                    },
                    self.vec3(node, "pos", [0.0; 3])?,
                )
            }
            other => return Err(self.err(node, &format!("geom type {other:?} is not supported"))),
        };
        if node.attribute("quat").is_some() || node.attribute("euler").is_some() {
            return Err(self.err(node, "rotated geoms are not supported"));
        }
        Ok(GeomDef {
            name,
            shape,
            pos,
            density,
            friction,
        })
    }

    fn actuator(&mut self, node: roxmltree::Node) -> Result<(), MjcfError> {
        if node.tag_name().name() != "position" {
            return Err(self.err(
                node,
                "only <position> actuators (PD servos with kp, kv) are supported",
            ));
        }
        let joint = node
            .attribute("joint")
            .ok_or_else(|| self.err(node, "needs `joint`"))?;
        let one = |attr: &str| -> Result<f64, MjcfError> {
            match self.floats(node, attr)? {
                Some(v) if v.len() == 1 && v[0] > 0.0 => Ok(v[0]),
                _ => Err(self.err(node, &format!("needs a positive `{attr}`"))),
            }
        };
        let kp = one("kp")?;
        let kd = one("kv")?;
        let limit = match self.floats(node, "forcerange")? {
            Some(r) if r.len() == 2 && r[1] > 0.0 && (r[0] + r[1]).abs() < 1e-9 => r[1],
            _ => return Err(self.err(node, "needs a symmetric `forcerange=\"-L L\"`")),
        };
        let err = self.err(node, &format!("no hinge named {joint:?}"));
        let dof = self.dofs.iter_mut().find(|d| d.name == joint).ok_or(err)?;
        dof.kp = kp;
        dof.kd = kd;
        dof.torque_limit = limit;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_attributes_and_unsupported_friction_are_errors_naming_them() {
        let with = |from: &str, to: &str| {
            let text = AMP_HUMANOID_XML.replacen(from, to, 1);
            CharacterModel::parse(&text, "x.xml")
                .unwrap_err()
                .to_string()
        };
        let e = with("armature=\"0.01\"", "armature=\"0.01\" stiffness=\"3\"");
        assert!(e.contains("stiffness"), "{e}");
        let e = with(
            "<joint name=\"abdomen_x\"",
            "<joint name=\"abdomen_x\" frictionloss=\"1\"",
        );
        assert!(e.contains("frictionloss") && e.contains("abdomen_x"), "{e}");
        let e = with(
            "friction=\"1.0 0.005 0.0001\"",
            "friction=\"1.0 0.5 0.0001\"",
        );
        assert!(e.contains("torsional"), "{e}");
        let e = with("armature=\"0.01\"", "armature=\"-1\"");
        assert!(e.contains("armature"), "{e}");
    }

    #[test]
    fn shipped_humanoid_matches_the_design() {
        let m = CharacterModel::amp_humanoid();
        assert_eq!(m.bodies.len(), 15);
        assert_eq!(m.dofs.len(), 28);
        let mass = m.total_mass();
        assert!((44.0..54.0).contains(&mass), "mass {mass}");
        let balls = m
            .bodies
            .iter()
            .filter(|b| matches!(b.joint, JointKind::Ball { .. }))
            .count();
        let hinges = m
            .bodies
            .iter()
            .filter(|b| matches!(b.joint, JointKind::Hinge { .. }))
            .count();
        assert_eq!(
            (balls, hinges),
            (8, 4),
            "abdomen, neck, 2 shoulders, 2 hips, 2 ankles; 2 elbows, 2 knees"
        );
        let fixed = m
            .bodies
            .iter()
            .filter(|b| b.joint == JointKind::Fixed)
            .count();
        assert_eq!(fixed, 2, "the hands");
        let knee = m.dofs.iter().find(|d| d.name == "left_knee").expect("knee");
        assert_eq!((knee.kp, knee.kd, knee.torque_limit), (500.0, 50.0, 150.0));
        // From <default><joint armature="0.01"> and <default><geom friction="1.0 ...">.
        assert!(m
            .dofs
            .iter()
            .all(|d| d.armature == 0.01 && d.damping == 0.0));
        assert!(m
            .bodies
            .iter()
            .flat_map(|b| &b.geoms)
            .all(|g| g.friction == 1.0));
        let abdomen = m
            .dofs
            .iter()
            .find(|d| d.name == "abdomen_y")
            .expect("abdomen");
        assert_eq!((abdomen.kp, abdomen.torque_limit), (1000.0, 200.0));
    }

    #[test]
    fn unsupported_or_broken_files_name_the_element() {
        let bad = AMP_HUMANOID_XML.replace(
            r#"<joint name="right_ankle_z" axis="0 0 1" range="-40 40"/>"#,
            "",
        );
        let e = CharacterModel::parse(&bad, "x.xml")
            .expect_err("2 hinges")
            .to_string();
        assert!(
            e.contains("x.xml") && e.contains("right_foot") && e.contains("2 hinges"),
            "{e}"
        );
        let bad = AMP_HUMANOID_XML.replace(
            r#"kp="500" kv="50" forcelimited="true" forcerange="-150 150"/>"#,
            r#"kp="abc"/>"#,
        );
        let e = CharacterModel::parse(&bad, "x.xml")
            .expect_err("bad kp")
            .to_string();
        assert!(e.contains("kp"), "{e}");
        let e = CharacterModel::parse("<mujoco><worldbody>", "x.xml")
            .expect_err("xml")
            .to_string();
        assert!(e.contains("not valid XML"), "{e}");
    }
}
