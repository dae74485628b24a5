// SPDX-License-Identifier: MIT
//! The app's event inbox and its WebSocket link to a bridge.
//!
//! Everything that happens (socket events, buttons, timers, pointer input) becomes an
//! [`Event`] in one [`Inbox`]; the app's single async loop takes them in order, so no state is
//! shared between callbacks.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use wasm_bindgen::prelude::*;
use webfusion_core::protocol::Control;

/// Something the app loop must handle.
#[derive(Debug)]
pub(crate) enum Event {
    /// The socket of connection `generation` opened.
    Opened { generation: u64 },
    /// A binary message arrived on connection `generation`.
    Received { generation: u64, bytes: Vec<u8> },
    /// Connection `generation` closed (or failed to open).
    Closed { generation: u64, code: u16, reason: String },
    /// Time to try connecting again (scheduled after a drop).
    Reconnect { generation: u64 },
    /// Time to look for frame reports (scheduled while frames are in flight).
    Poll,
    /// A button, input or view gesture.
    Ui(Ui),
}

/// User actions.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Ui {
    Connect,
    Disconnect,
    /// Play, pause, step, seek or loop; the app decides what reaches the bridge.
    Playback(Control),
    /// The rate input's text, checked by the app before anything reaches the bridge.
    Rate(String),
    /// Test hook (`window.webfusion.lose_device()`): destroys the GPU device, as a driver
    /// reset or a GPU process crash would, to exercise the rebuild.
    LoseDevice,
    EveryFrame(bool),
    ApplySettings,
    Reset,
    ExportPly,
    ExportGlb,
    /// The world model's scene (textured planes and the rest of the mesh) as `.glb`.
    ExportScene,
    ExportTrajectory,
    /// Orbit (dx, dy in pixels), pan (dx, dy) or zoom (factor) of the free view.
    Orbit(f32, f32),
    Pan(f32, f32),
    Zoom(f32),
    /// Show the model's fused colour instead of shading in the free view.
    ViewColour(bool),
    /// Draw the world model's textured planes in the free view.
    ViewPlanes(bool),
    /// The odometry view's next stage (after the last: the next frame, paused).
    OdometryStage,
    /// The virtual sensor: render at the pose typed into its panel, at the free view's camera,
    /// or at the last real frame's pose (beside its depth).
    SimRender,
    SimFromView,
    SimAtFrame,
    /// Render at the trajectory's pose whose index is typed into the panel.
    SimAtTrajectory,
    /// Render at every real frame's pose as it arrives.
    SimFollow(bool),
    /// The noise checkbox or its seed changed.
    SimNoise,
    SimDownload,
    /// Open the saved map chosen in the file input, or the bridge's (`serve --map`); close it.
    OpenMapFile,
    MapFromBridge,
    CloseMap,
}

/// Events waiting for the app loop, and the loop's wake-up call.
#[derive(Default)]
pub(crate) struct Inbox {
    events: RefCell<VecDeque<Event>>,
    wake: RefCell<Option<js_sys::Function>>,
}

impl Inbox {
    pub(crate) fn push(&self, event: Event) {
        self.events.borrow_mut().push_back(event);
        if let Some(wake) = self.wake.borrow_mut().take() {
            wake.call0(&JsValue::NULL).ok();
        }
    }

    /// The next event, without waiting.
    pub(crate) fn try_next(&self) -> Option<Event> {
        self.events.borrow_mut().pop_front()
    }

    /// The next event, waiting for one.
    pub(crate) async fn next(&self) -> Event {
        loop {
            if let Some(event) = self.try_next() {
                return event;
            }
            let promise = js_sys::Promise::new(&mut |resolve, _reject| {
                *self.wake.borrow_mut() = Some(resolve);
            });
            wasm_bindgen_futures::JsFuture::from(promise).await.ok();
        }
    }
}

/// One WebSocket connection and the callbacks that feed the inbox; closing or dropping it
/// detaches the callbacks first, so a dead socket never speaks again.
pub(crate) struct Link {
    socket: web_sys::WebSocket,
    _callbacks: Vec<Closure<dyn FnMut(JsValue)>>,
}

impl Link {
    /// Opens `url` (a `ws://` or `wss://` URL, the token already in its query).
    pub(crate) fn open(url: &str, generation: u64, inbox: &Rc<Inbox>) -> Result<Self, String> {
        let socket = web_sys::WebSocket::new(url).map_err(|e| format!("cannot open {url}: {}", js_text(&e)))?;
        socket.set_binary_type(web_sys::BinaryType::Arraybuffer);
        let mut callbacks: Vec<Closure<dyn FnMut(JsValue)>> = Vec::new();
        let on_open = {
            let inbox = Rc::clone(inbox);
            Closure::<dyn FnMut(JsValue)>::new(move |_| inbox.push(Event::Opened { generation }))
        };
        socket.set_onopen(Some(on_open.as_ref().unchecked_ref()));
        callbacks.push(on_open);
        let on_message = {
            let inbox = Rc::clone(inbox);
            Closure::<dyn FnMut(JsValue)>::new(move |event: JsValue| {
                let Ok(event) = event.dyn_into::<web_sys::MessageEvent>() else { return };
                let data = event.data();
                if let Some(buffer) = data.dyn_ref::<js_sys::ArrayBuffer>() {
                    inbox.push(Event::Received { generation, bytes: js_sys::Uint8Array::new(buffer).to_vec() });
                } else {
                    // Text is not part of the protocol: let the decoder name the problem.
                    inbox.push(Event::Received { generation, bytes: data.as_string().unwrap_or_default().into_bytes() });
                }
            })
        };
        socket.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        callbacks.push(on_message);
        let on_close = {
            let inbox = Rc::clone(inbox);
            Closure::<dyn FnMut(JsValue)>::new(move |event: JsValue| {
                let (code, reason) = match event.dyn_into::<web_sys::CloseEvent>() {
                    Ok(close) => (close.code(), close.reason()),
                    Err(_) => (1006, String::new()),
                };
                inbox.push(Event::Closed { generation, code, reason });
            })
        };
        socket.set_onclose(Some(on_close.as_ref().unchecked_ref()));
        callbacks.push(on_close);
        Ok(Self { socket, _callbacks: callbacks })
    }

    /// Sends one binary message; false when the socket is not open.
    pub(crate) fn send(&self, bytes: &[u8]) -> bool {
        self.socket.ready_state() == web_sys::WebSocket::OPEN && self.socket.send_with_u8_array(bytes).is_ok()
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.socket.set_onopen(None);
        self.socket.set_onmessage(None);
        self.socket.set_onclose(None);
        self.socket.close().ok();
    }
}

/// Calls `inbox.push(event)` after `delay_ms`.
pub(crate) fn push_later(inbox: &Rc<Inbox>, delay_ms: i32, event: Event) {
    let inbox = Rc::clone(inbox);
    let mut event = Some(event);
    let callback = Closure::once_into_js(move || {
        if let Some(event) = event.take() {
            inbox.push(event);
        }
    });
    if let Some(window) = web_sys::window() {
        window.set_timeout_with_callback_and_timeout_and_arguments_0(callback.unchecked_ref(), delay_ms).ok();
    }
}

/// A JavaScript value (usually an exception) as text.
pub(crate) fn js_text(value: &JsValue) -> String {
    value
        .as_string()
        .or_else(|| value.dyn_ref::<js_sys::Error>().map(|e| String::from(e.message())))
        .unwrap_or_else(|| format!("{value:?}"))
}
