//! The live session's shared state and the client messages that change it,
//! each checked before anything changes (docs/live-protocol.md).

use super::EyeView;
use anyhow::{bail, ensure, Context, Result};
use glam::{DMat3, DQuat, DVec3, EulerRot};
use parallax_common::camera::Placement;
use parallax_common::config::{Display, Scene};
use parallax_common::protocol::{LayerControl, StreamImage};
use parallax_common::tf::TransferFunction;
use parallax_common::tools::{EnhancerKind, Tool, MAX_ENHANCERS};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Everything a client can change; what a copied link carries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveState {
    pub placement: Placement,
    pub eta: f64,
    pub accuracy: f64,
    pub step_factor: f64,
    pub gamma: f64,
    pub tf: TransferFunction,
    #[serde(with = "parallax_common::tools::list")]
    pub tools: Vec<Tool>,
    /// "desktop", a projector id, or "eye".
    pub output: String,
    pub eye_x: f64,
    #[serde(default)]
    pub recording: bool,
    /// Whether the tools' geometry and the cursor are drawn over the views
    /// (`render.overlay.show`).
    #[serde(default)]
    pub overlay: bool,
    /// The 3D cursor (m, display space), moved by dragging in the view.
    #[serde(default)]
    pub cursor: Option<[f64; 3]>,
    /// The scene's registered layers: each one shown or not, and its
    /// opacity (`[[layer]]` order).
    #[serde(default)]
    pub layers: Vec<LayerControl>,
    /// Their transfer functions (the scene's files, then as edited).
    #[serde(default)]
    pub layer_tfs: Vec<TransferFunction>,
    /// The scene's time steps (its `series`' length, 1 without one): the
    /// page's slider runs over them. Not a client's to set.
    #[serde(default = "one_step")]
    pub steps: u32,
    /// The time step drawn, and the playback.
    #[serde(default)]
    pub time: TimeControl,
}

fn one_step() -> u32 {
    1
}

/// A series' playback (`time` messages): the step drawn, whether it
/// advances by itself, and at how many steps a second (wrapping to the
/// first after the last).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeControl {
    pub step: u32,
    pub playing: bool,
    pub rate: f64,
}

impl Default for TimeControl {
    fn default() -> Self {
        TimeControl {
            step: 0,
            playing: false,
            rate: 2.0,
        }
    }
}

/// A transfer function point as the page sends it.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMsg {
    value: f64,
    color: [f64; 3],
    extinction: f64,
    importance: Option<f64>,
    refraction: Option<f64>,
}

/// A client's message (docs/live-protocol.md).
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ClientMsg {
    Rotate {
        dx: f64,
        dy: f64,
    },
    Zoom {
        factor: f64,
    },
    Pan {
        dx: f64,
        dy: f64,
    },
    Set {
        eta: Option<f64>,
        accuracy: Option<f64>,
        step_factor: Option<f64>,
        gamma: Option<f64>,
        /// Draw the tools' geometry and the cursor.
        #[serde(default)]
        overlay: Option<bool>,
    },
    /// Places the 3D cursor (m, display space), or removes it (null).
    Cursor {
        point: Option<[f64; 3]>,
    },
    Tf {
        point: Vec<PointMsg>,
    },
    /// Changes fields of a tool.
    Tool(Box<ToolEdit>),
    /// Adds a tool at the chain's end: a `[[tool]]` table as JSON.
    AddTool {
        tool: serde_json::Value,
    },
    /// Removes tool `index`.
    RemoveTool {
        index: usize,
    },
    /// Shows or hides registered layer `index`, or sets its opacity.
    Layer {
        index: usize,
        visible: Option<bool>,
        opacity: Option<f64>,
    },
    /// Moves through the scene's time series: the step drawn, playback on
    /// or off, its rate in steps a second.
    Time {
        step: Option<u32>,
        playing: Option<bool>,
        rate: Option<f64>,
    },
    /// Replaces registered layer `index`'s transfer function.
    LayerTf {
        index: usize,
        point: Vec<PointMsg>,
    },
    /// Moves tool `from` to place `to` of the chain (enhancers act in
    /// chain order).
    MoveTool {
        from: usize,
        to: usize,
    },
    Output {
        output: String,
        eye_x: Option<f64>,
    },
    Focus {
        x: f64,
        y: f64,
    },
    /// Grows band picker `index`'s band from the point the click at (x, y)
    /// picks (region growing, G10 §4), within `tolerance` × the transfer
    /// function's value span of its value.
    GrowBand {
        index: usize,
        x: f64,
        y: f64,
        tolerance: Option<f64>,
    },
    Record {
        on: bool,
    },
    State {
        state: Box<LiveState>,
    },
    Quit,
}

/// A `tool` message: any fields of tool `index`'s kind, as in its
/// `[[tool]]` table (common/src/tools.rs); a field the kind does not have
/// is refused by name.
#[derive(Clone, Debug, Deserialize)]
pub struct ToolEdit {
    index: usize,
    #[serde(flatten)]
    fields: serde_json::Map<String, serde_json::Value>,
}

/// How far the volume's centre may be from the screen's (m, per axis):
/// pan and focus stop there, and a state is refused beyond it, so every
/// state the server sends can be applied again from its link.
pub const CENTER_LIMIT: f64 = parallax_common::tools::REACH_M;

/// The default `grow-band` tolerance: a twentieth of the transfer
/// function's value span.
pub const GROW_TOLERANCE: f64 = 0.05;

/// Transfer-function points a page may send, in a `tf` or a `state`.
const MAX_TF_POINTS: usize = 256;

/// `v` if it is finite and within [lo, hi]; otherwise an error naming it.
fn within(name: &str, v: f64, lo: f64, hi: f64) -> Result<f64> {
    ensure!(
        v.is_finite() && (lo..=hi).contains(&v),
        "{name}: {v} is outside [{lo}, {hi}]"
    );
    Ok(v)
}

fn within3(name: &str, v: [f64; 3], lo: f64, hi: f64) -> Result<[f64; 3]> {
    for c in v {
        within(name, c, lo, hi)?;
    }
    Ok(v)
}

/// The outputs a display offers: the desktop window, or each projector and
/// the simulated eye view of a light field display.
pub fn outputs(display: &Display) -> Vec<String> {
    if display.projectors.len() == 1 {
        vec!["desktop".into()]
    } else {
        let mut v: Vec<String> = display.projectors.iter().map(|p| p.id.clone()).collect();
        v.push("eye".into());
        v
    }
}

/// The page's first message.
pub fn hello(
    scene_path: &Path,
    scene: &Scene,
    display: &Display,
    tf: &TransferFunction,
    record_dir: &Path,
) -> serde_json::Value {
    let p = tf.points();
    let range = [p[0].value, p[p.len() - 1].value];
    let w = display.screen.size[0];
    serde_json::json!({
        "type": "hello",
        "scene": scene_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        "outputs": outputs(display),
        "value_range": range,
        "tool_kinds": scene.tools.iter().map(|t| t.enhancer().file()).collect::<Vec<_>>(),
        "all_tool_kinds": EnhancerKind::ALL.iter().map(|k| k.file()).collect::<Vec<_>>(),
        // Each kind's field hints and what "add" adds (tools are data).
        "tool_info": EnhancerKind::ALL
            .iter()
            .map(|k| (k.file().to_string(), k.page_info(range)))
            .collect::<serde_json::Map<_, _>>(),
        "eye_range": [-w, w],
        // The registered layers, named by their volume and function files.
        "layers": scene.layers.iter().map(|l| {
            let name = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            format!("{} · {}", name(&l.volume), name(l.function_file().1))
        }).collect::<Vec<_>>(),
        "record_dir": record_dir.display().to_string(),
    })
}

impl LiveState {
    /// The state a session starts from: the scene, its display, its
    /// transfer function and its layers' (`layer_tfs`, `[[layer]]` order).
    pub fn from_scene(
        scene: &Scene,
        display: &Display,
        tf: TransferFunction,
        layer_tfs: Vec<TransferFunction>,
    ) -> Self {
        LiveState {
            placement: scene.placement,
            eta: scene.render.eta,
            accuracy: scene.render.accuracy,
            step_factor: scene.render.step_factor,
            gamma: scene.render.gamma,
            tf,
            tools: scene.tools.clone(),
            output: if display.projectors.len() == 1 {
                "desktop".into()
            } else {
                "eye".into()
            },
            eye_x: display.observer.position[0],
            recording: false,
            overlay: scene.render.overlay.show,
            cursor: scene.render.overlay.cursor,
            layers: scene.layers.iter().map(LayerControl::from).collect(),
            layer_tfs,
            steps: scene.steps() as u32,
            time: TimeControl::default(),
        }
    }

    /// Applies a state-changing message (not focus or quit); on error the
    /// state may be half changed, so the caller applies it to a copy.
    pub fn apply(&mut self, msg: ClientMsg, display: &Display) -> Result<()> {
        match msg {
            ClientMsg::Rotate { dx, dy } => {
                let dx = within("rotate.dx", dx, -360.0, 360.0)?;
                let dy = within("rotate.dy", dy, -360.0, 360.0)?;
                let turn = DMat3::from_rotation_y(dx.to_radians())
                    * DMat3::from_rotation_x(dy.to_radians());
                self.placement.rotation_deg = euler_deg(turn * self.placement.rotation());
            }
            ClientMsg::Layer {
                index,
                visible,
                opacity,
            } => {
                let n = self.layers.len();
                let l = self
                    .layers
                    .get_mut(index)
                    .with_context(|| format!("layer.index {index}: the scene has {n} layers"))?;
                if let Some(v) = visible {
                    l.visible = v;
                }
                if let Some(o) = opacity {
                    l.opacity = within("layer.opacity", o, 0.0, 1.0)?;
                }
            }
            ClientMsg::Zoom { factor } => {
                let f = within("zoom.factor", factor, 0.1, 10.0)?;
                self.placement.size =
                    within("placement.size", self.placement.size * f, 1e-4, 100.0)
                        .context("zoom: the volume would be too small or too large")?;
            }
            ClientMsg::Pan { dx, dy } => {
                let dx = within("pan.dx", dx, -10.0, 10.0)?;
                let dy = within("pan.dy", dy, -10.0, 10.0)?;
                let c = &mut self.placement.center;
                c[0] = (c[0] + dx).clamp(-CENTER_LIMIT, CENTER_LIMIT);
                c[1] = (c[1] + dy).clamp(-CENTER_LIMIT, CENTER_LIMIT);
            }
            ClientMsg::Set {
                eta,
                accuracy,
                step_factor,
                gamma,
                overlay,
            } => {
                if let Some(on) = overlay {
                    self.overlay = on;
                }
                if let Some(v) = eta {
                    self.eta = within("set.eta", v, 0.0, 1.0)?;
                }
                if let Some(v) = accuracy {
                    self.accuracy = within("set.accuracy", v, 0.05, 64.0)?;
                }
                if let Some(v) = step_factor {
                    self.step_factor = within("set.step_factor", v, 0.01, 8.0)?;
                }
                if let Some(v) = gamma {
                    self.gamma = within("set.gamma", v, 0.0, 1.0)?;
                }
            }
            ClientMsg::Time {
                step,
                playing,
                rate,
            } => {
                if let Some(s) = step {
                    ensure!(
                        s < self.steps,
                        "time.step {s}: the scene has {} time step(s), 0 to {}",
                        self.steps,
                        self.steps - 1
                    );
                    self.time.step = s;
                }
                if let Some(r) = rate {
                    self.time.rate = within("time.rate", r, 0.01, 240.0)?;
                }
                if let Some(p) = playing {
                    ensure!(
                        !p || self.steps > 1,
                        "time.playing: the scene has one time step (no series)"
                    );
                    self.time.playing = p;
                }
            }
            ClientMsg::Tf { point } => self.tf = transfer_function("tf", point)?,
            ClientMsg::LayerTf { index, point } => {
                let n = self.layer_tfs.len();
                ensure!(
                    index < n,
                    "layer-tf.index {index}: the scene has {n} layers"
                );
                self.layer_tfs[index] = transfer_function("layer-tf", point)?;
            }
            ClientMsg::Tool(edit) => self.edit_tool(&edit)?,
            ClientMsg::AddTool { tool } => {
                ensure!(
                    self.tools.len() < MAX_ENHANCERS,
                    "add-tool: the chain holds {MAX_ENHANCERS} tools at most"
                );
                let t = Tool::from_table(tool, "add-tool.tool")?;
                t.bounds("add-tool.tool")?;
                t.check("add-tool.tool")?;
                self.tools.push(t);
            }
            ClientMsg::RemoveTool { index } => {
                ensure!(
                    index < self.tools.len(),
                    "remove-tool.index: {index}, the scene has {} tool(s)",
                    self.tools.len()
                );
                self.tools.remove(index);
            }
            ClientMsg::MoveTool { from, to } => {
                let n = self.tools.len();
                ensure!(
                    from < n,
                    "move-tool.from: {from}, the scene has {n} tool(s)"
                );
                ensure!(to < n, "move-tool.to: {to}, the scene has {n} tool(s)");
                let t = self.tools.remove(from);
                self.tools.insert(to, t);
            }
            ClientMsg::Cursor { point } => {
                if let Some(p) = point {
                    within3("cursor.point", p, -CENTER_LIMIT, CENTER_LIMIT)?;
                }
                self.cursor = point;
            }
            ClientMsg::Output { output, eye_x } => {
                ensure!(
                    outputs(display).contains(&output),
                    "output: '{output}' is not one of {:?}",
                    outputs(display)
                );
                self.output = output;
                if let Some(x) = eye_x {
                    self.eye_x = within("output.eye_x", x, -10.0, 10.0)?;
                }
            }
            ClientMsg::Record { on } => self.recording = on,
            ClientMsg::State { state } => self.set_state(*state, display)?,
            ClientMsg::Focus { .. } | ClientMsg::GrowBand { .. } | ClientMsg::Quit => {
                bail!("not a state change")
            }
        }
        Ok(())
    }
}

impl LiveState {
    /// Fields of a tool changed: each given field replaces the tool's (a
    /// field its kind does not have is refused by name), then the tool is
    /// checked whole.
    fn edit_tool(&mut self, edit: &ToolEdit) -> Result<()> {
        let (index, n) = (edit.index, self.tools.len());
        let tool = self
            .tools
            .get_mut(index)
            .with_context(|| format!("tool.index: {index}, the scene has {n} tool(s)"))?;
        ensure!(
            !edit.fields.contains_key("kind"),
            "tool.kind: a tool's kind does not change; remove it and add another"
        );
        let mut table = tool.table()?;
        table.extend(edit.fields.clone());
        let kind = tool.enhancer().file();
        let edited = Tool::from_table(table.into(), &format!("tool {index} ({kind})"))?;
        edited.bounds("tool")?;
        edited.check(&format!("tool {index}"))?;
        *tool = edited;
        Ok(())
    }

    /// Whether `grow-band` may grow tool `index`'s band.
    pub fn check_grow(&self, index: usize, tolerance: f64) -> Result<()> {
        within("grow-band.tolerance", tolerance, 0.0, 1.0)?;
        match self.tools.get(index) {
            Some(Tool::BandPicker(_)) => Ok(()),
            Some(t) => bail!(
                "grow-band.index: tool {index} is a {}, not a band picker",
                t.enhancer().file()
            ),
            None => bail!(
                "grow-band.index: {index}, the scene has {} tool(s)",
                self.tools.len()
            ),
        }
    }

    /// Sets band picker `index`'s band (by value).
    pub fn set_band(&mut self, index: usize, band: [f64; 4]) -> Result<()> {
        match self.tools.get_mut(index) {
            Some(Tool::BandPicker(b)) => {
                let next = Tool::BandPicker(parallax_common::tools::BandPicker {
                    band,
                    points: None,
                    ..*b
                });
                next.bounds("grow-band")?;
                next.check("grow-band")?;
                self.tools[index] = next;
                Ok(())
            }
            _ => bail!("tool {index} is no longer a band picker"),
        }
    }

    /// A whole state at once (a reload, a second page): every field through
    /// the same checks as its own message, applied only if all pass.
    fn set_state(&mut self, s: LiveState, display: &Display) -> Result<()> {
        let mut next = self.clone();
        next.placement = s.placement;
        within3(
            "state.placement.center",
            s.placement.center,
            -CENTER_LIMIT,
            CENTER_LIMIT,
        )?;
        within3(
            "state.placement.rotation_deg",
            s.placement.rotation_deg,
            -1e4,
            1e4,
        )?;
        within("state.placement.size", s.placement.size, 1e-4, 100.0)?;
        next.apply(
            ClientMsg::Set {
                eta: Some(s.eta),
                accuracy: Some(s.accuracy),
                step_factor: Some(s.step_factor),
                gamma: Some(s.gamma),
                overlay: Some(s.overlay),
            },
            display,
        )?;
        next.apply(ClientMsg::Cursor { point: s.cursor }, display)?;
        next.apply(
            ClientMsg::Time {
                step: Some(s.time.step),
                playing: Some(s.time.playing),
                rate: Some(s.time.rate),
            },
            display,
        )?;
        let n = s.tf.points().len();
        ensure!(
            (2..=MAX_TF_POINTS).contains(&n),
            "state.tf: {n} points (2 to {MAX_TF_POINTS})"
        );
        next.tf = TransferFunction::from_points(s.tf.points().to_vec()).context("state.tf")?;
        ensure!(
            s.layer_tfs.len() == next.layer_tfs.len(),
            "state.layer_tfs: {} functions, the scene has {} layers",
            s.layer_tfs.len(),
            next.layer_tfs.len()
        );
        for (i, t) in s.layer_tfs.iter().enumerate() {
            let n = t.points().len();
            ensure!(
                (2..=MAX_TF_POINTS).contains(&n),
                "state.layer_tfs {i}: {n} points (2 to {MAX_TF_POINTS})"
            );
            next.layer_tfs[i] = TransferFunction::from_points(t.points().to_vec())
                .with_context(|| format!("state.layer_tfs {i}"))?;
        }
        ensure!(
            s.tools.len() <= MAX_ENHANCERS,
            "state.tools: {} tools, at most {MAX_ENHANCERS} can be chained",
            s.tools.len()
        );
        for (i, t) in s.tools.iter().enumerate() {
            t.bounds(&format!("state.tools {i}"))?;
            t.check(&format!("state.tools {i}"))?;
        }
        next.tools = s.tools;
        ensure!(
            s.layers.len() == next.layers.len(),
            "state.layers: {} layers, the scene has {}",
            s.layers.len(),
            next.layers.len()
        );
        for (i, l) in s.layers.iter().enumerate() {
            next.apply(
                ClientMsg::Layer {
                    index: i,
                    visible: Some(l.visible),
                    opacity: Some(l.opacity),
                },
                display,
            )?;
        }
        next.apply(
            ClientMsg::Output {
                output: s.output,
                eye_x: Some(s.eye_x),
            },
            display,
        )?;
        *self = next;
        Ok(())
    }

    /// The eye of the streamed output: the observer, or the moved eye of
    /// the eye view.
    fn eye(&self, display: &Display) -> [f64; 3] {
        let o = display.observer.position;
        if self.output == "eye" {
            [self.eye_x, o[1], o[2]]
        } else {
            o
        }
    }

    /// The projectors whose images this state's output needs.
    pub fn streamed(&self, display: &Display) -> Vec<u32> {
        match self.projector(display) {
            Some(i) => vec![i as u32],
            None => (0..display.projectors.len() as u32).collect(),
        }
    }

    fn projector(&self, display: &Display) -> Option<usize> {
        if self.output == "desktop" {
            return Some(0);
        }
        display.projectors.iter().position(|p| p.id == self.output)
    }

    /// The streamed output of one frame: width, height, sRGB RGB.
    pub fn image(
        &self,
        display: &Display,
        images: &[StreamImage],
        eye_view: EyeView,
    ) -> Result<(u32, u32, Vec<u8>)> {
        match self.projector(display) {
            Some(i) => {
                let im = images
                    .iter()
                    .find(|im| im.projector as usize == i)
                    .context("the streamed projector's image did not arrive")?;
                Ok((im.width, im.height, im.rgb8.clone()))
            }
            None => eye_view(display, images, self.eye(display)),
        }
    }

    /// The display-space ray through the point (x, y) ∈ [0, 1]² (0, 0 at the
    /// top left) of the streamed image: from the output's eye through that
    /// point of its screen region.
    pub fn focus_ray(&self, display: &Display, x: f64, y: f64) -> Result<[[f64; 3]; 2]> {
        let x = within("x", x, 0.0, 1.0)?;
        let y = within("y", y, 0.0, 1.0)?;
        let [sw, sh] = display.screen.size;
        let region = match self.projector(display) {
            Some(i) => display.views(self.eta)[i].region,
            None => [-sw / 2.0, -sh / 2.0, sw, sh],
        };
        let q = DVec3::new(
            region[0] + x * region[2],
            region[1] + (1.0 - y) * region[3],
            0.0,
        );
        let eye = DVec3::from(self.eye(display));
        let d = q - eye;
        ensure!(d.length() > 1e-12, "the eye lies on the screen");
        Ok([eye.into(), d.normalize().into()])
    }
}

/// Placement's x-then-y-then-z fixed-axis angles (degrees) of a rotation.
fn euler_deg(r: DMat3) -> [f64; 3] {
    let (z, y, x) = DQuat::from_mat3(&r).normalize().to_euler(EulerRot::ZYX);
    [x.to_degrees(), y.to_degrees(), z.to_degrees()]
}

/// A transfer function from a page's points (`what`: the message, for the
/// errors).
fn transfer_function(what: &str, point: Vec<PointMsg>) -> Result<TransferFunction> {
    ensure!(
        (2..=MAX_TF_POINTS).contains(&point.len()),
        "{what}.point: {} points (2 to {MAX_TF_POINTS})",
        point.len()
    );
    let pts = point
        .into_iter()
        .map(|p| {
            let mut c = parallax_common::tf::ControlPoint::new(p.value, p.color, p.extinction);
            if let Some(i) = p.importance {
                c.importance = i;
            }
            if let Some(r) = p.refraction {
                c.refraction = r;
            }
            c
        })
        .collect();
    TransferFunction::from_points(pts).context(what.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_round_trip_through_placement() {
        let p = Placement {
            center: [0.0; 3],
            rotation_deg: [-90.0, 180.0, 0.0],
            size: 1.0,
        };
        let back = euler_deg(p.rotation());
        let q = Placement {
            rotation_deg: back,
            ..p
        };
        let d = (q.rotation() - p.rotation()).to_cols_array();
        assert!(d.iter().all(|v| v.abs() < 1e-12), "{back:?}");
    }

    #[test]
    fn a_drag_turns_about_the_screen_axes() {
        let mut p = Placement {
            center: [0.0; 3],
            rotation_deg: [10.0, 20.0, 30.0],
            size: 1.0,
        };
        let before = p.rotation();
        p.rotation_deg = euler_deg(DMat3::from_rotation_y(15f64.to_radians()) * before);
        let expect = DMat3::from_rotation_y(15f64.to_radians()) * before;
        let d = (p.rotation() - expect).to_cols_array();
        assert!(d.iter().all(|v| v.abs() < 1e-12));
    }
}
