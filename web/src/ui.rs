// SPDX-License-Identifier: MIT
//! DOM plumbing: elements by id, form values, URL parameters, remembered settings, buttons and
//! pointer gestures wired to the inbox, and downloads.

use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

use wasm_bindgen::prelude::*;
use webfusion_core::protocol::Control;

use crate::link::{Event, Inbox, Ui};

pub(crate) fn document() -> web_sys::Document {
    web_sys::window().and_then(|w| w.document()).expect("the app runs in a page with a document")
}

pub(crate) fn element<T: JsCast>(id: &str) -> Result<T, String> {
    document().get_element_by_id(id).ok_or_else(|| format!("the page has no #{id}"))?.dyn_into::<T>().map_err(|_| format!("#{id} has the wrong element type"))
}

pub(crate) fn set_text(id: &str, text: &str) {
    if let Some(el) = document().get_element_by_id(id) {
        el.set_text_content(Some(text));
    }
}

/// The value of an `<input>` or `<select>` (empty when missing).
pub(crate) fn value(id: &str) -> String {
    let Some(el) = document().get_element_by_id(id) else { return String::new() };
    if let Some(input) = el.dyn_ref::<web_sys::HtmlInputElement>() {
        if input.type_() == "checkbox" {
            return if input.checked() { "1".to_owned() } else { String::new() };
        }
        return input.value();
    }
    el.dyn_ref::<web_sys::HtmlSelectElement>().map(web_sys::HtmlSelectElement::value).unwrap_or_default()
}

pub(crate) fn set_value(id: &str, text: &str) {
    let Some(el) = document().get_element_by_id(id) else { return };
    if let Some(input) = el.dyn_ref::<web_sys::HtmlInputElement>() {
        if input.type_() == "checkbox" {
            input.set_checked(matches!(text, "1" | "true" | "on"));
        } else {
            input.set_value(text);
        }
    } else if let Some(select) = el.dyn_ref::<web_sys::HtmlSelectElement>() {
        select.set_value(text);
    }
}

pub(crate) fn set_disabled(id: &str, disabled: bool) {
    if let Some(el) = document().get_element_by_id(id) {
        if disabled {
            el.set_attribute("disabled", "").ok();
        } else {
            el.remove_attribute("disabled").ok();
        }
    }
}

/// The page URL's query parameters.
pub(crate) fn query() -> HashMap<String, String> {
    let search = web_sys::window().and_then(|w| w.location().search().ok()).unwrap_or_default();
    let Ok(params) = web_sys::UrlSearchParams::new_with_str(&search) else { return HashMap::new() };
    let mut out = HashMap::new();
    for entry in params.entries() {
        let Ok(pair) = entry else { continue };
        let pair: js_sys::Array = pair.unchecked_into();
        if let (Some(k), Some(v)) = (pair.get(0).as_string(), pair.get(1).as_string()) {
            out.insert(k, v);
        }
    }
    out
}

pub(crate) fn local_get(key: &str) -> Option<String> {
    web_sys::window()?.local_storage().ok()??.get_item(key).ok()?
}

pub(crate) fn local_set(key: &str, value: &str) {
    if let Some(storage) = web_sys::window().and_then(|w| w.local_storage().ok().flatten()) {
        storage.set_item(key, value).ok();
    }
}

/// The bridge URL of the page's own server: `ws(s)://host/ws`.
pub(crate) fn own_bridge_url() -> String {
    let location = web_sys::window().map(|w| w.location());
    let host = location.as_ref().and_then(|l| l.host().ok()).unwrap_or_else(|| "127.0.0.1:8080".to_owned());
    let secure = location.and_then(|l| l.protocol().ok()).is_some_and(|p| p == "https:");
    format!("{}://{host}/ws", if secure { "wss" } else { "ws" })
}

/// Makes `id` push `make()` into the inbox on `event` (a missing element is skipped).
fn on(inbox: &Rc<Inbox>, id: &str, event: &str, make: impl Fn() -> Option<Ui> + 'static) {
    let Some(el) = document().get_element_by_id(id) else { return };
    let inbox = Rc::clone(inbox);
    let callback = Closure::<dyn FnMut()>::new(move || {
        if let Some(ui) = make() {
            inbox.push(Event::Ui(ui));
        }
    });
    el.add_event_listener_with_callback(event, callback.as_ref().unchecked_ref()).ok();
    // The page lives as long as the app: the listener stays.
    callback.forget();
}

/// Wires the page's buttons and inputs to the inbox.
pub(crate) fn bind_controls(inbox: &Rc<Inbox>) {
    for (id, ui) in [
        ("connect", Ui::Connect),
        ("disconnect", Ui::Disconnect),
        ("play", Ui::Playback(Control::Play)),
        ("pause", Ui::Playback(Control::Pause)),
        ("step", Ui::Playback(Control::Step)),
        ("apply", Ui::ApplySettings),
        ("reset", Ui::Reset),
        ("export-ply", Ui::ExportPly),
        ("export-glb", Ui::ExportGlb),
        ("export-scene", Ui::ExportScene),
        ("export-trajectory", Ui::ExportTrajectory),
        ("odometry-step", Ui::OdometryStage),
        ("sim-render", Ui::SimRender),
        ("sim-from-view", Ui::SimFromView),
        ("sim-at-frame", Ui::SimAtFrame),
        ("sim-at-trajectory", Ui::SimAtTrajectory),
        ("sim-download", Ui::SimDownload),
        ("map-from-bridge", Ui::MapFromBridge),
        ("map-close", Ui::CloseMap),
    ] {
        on(inbox, id, "click", move || Some(ui.clone()));
    }
    on(inbox, "seek", "change", || value("seek").parse().ok().map(|i| Ui::Playback(Control::Seek(i))));
    on(inbox, "rate", "change", || Some(Ui::Rate(value("rate"))));
    on(inbox, "loop", "change", || Some(Ui::Playback(Control::Loop(!value("loop").is_empty()))));
    on(inbox, "every-frame", "change", || Some(Ui::EveryFrame(!value("every-frame").is_empty())));
    on(inbox, "free-colour", "change", || Some(Ui::ViewColour(!value("free-colour").is_empty())));
    on(inbox, "free-planes", "change", || Some(Ui::ViewPlanes(!value("free-planes").is_empty())));
    on(inbox, "sim-follow", "change", || Some(Ui::SimFollow(!value("sim-follow").is_empty())));
    on(inbox, "sim-noise", "change", || Some(Ui::SimNoise));
    on(inbox, "sim-seed", "change", || Some(Ui::SimNoise));
    on(inbox, "open-map", "change", || Some(Ui::OpenMapFile));
}

/// Orbit (drag), pan (shift- or right-drag, two-finger drag) and zoom (wheel, pinch) on the
/// free-view canvas.
pub(crate) fn bind_gestures(inbox: &Rc<Inbox>, canvas: &web_sys::HtmlCanvasElement) {
    let pointers: Rc<RefCell<HashMap<i32, (f32, f32)>>> = Rc::default();
    let listen = |event: &str, callback: Closure<dyn FnMut(web_sys::PointerEvent)>| {
        canvas.add_event_listener_with_callback(event, callback.as_ref().unchecked_ref()).ok();
        callback.forget();
    };
    {
        let pointers = Rc::clone(&pointers);
        let target = canvas.clone();
        listen(
            "pointerdown",
            Closure::new(move |e: web_sys::PointerEvent| {
                target.set_pointer_capture(e.pointer_id()).ok();
                pointers.borrow_mut().insert(e.pointer_id(), (e.client_x() as f32, e.client_y() as f32));
            }),
        );
    }
    for end in ["pointerup", "pointercancel"] {
        let pointers = Rc::clone(&pointers);
        listen(
            end,
            Closure::new(move |e: web_sys::PointerEvent| {
                pointers.borrow_mut().remove(&e.pointer_id());
            }),
        );
    }
    {
        let inbox = Rc::clone(inbox);
        listen(
            "pointermove",
            Closure::new(move |e: web_sys::PointerEvent| {
                let mut map = pointers.borrow_mut();
                let Some(&(x0, y0)) = map.get(&e.pointer_id()) else { return };
                let (x, y) = (e.client_x() as f32, e.client_y() as f32);
                if map.len() >= 2 {
                    // Pinch: zoom by the change of the two fingers' distance, pan by half the motion.
                    let other = map.iter().find(|(id, _)| **id != e.pointer_id()).map(|(_, p)| *p).unwrap_or((x0, y0));
                    let before = ((x0 - other.0).powi(2) + (y0 - other.1).powi(2)).sqrt().max(1.0);
                    let after = ((x - other.0).powi(2) + (y - other.1).powi(2)).sqrt().max(1.0);
                    inbox.push(Event::Ui(Ui::Zoom(before / after)));
                    inbox.push(Event::Ui(Ui::Pan((x - x0) / 2.0, (y - y0) / 2.0)));
                } else if e.shift_key() || e.buttons() & 2 != 0 {
                    inbox.push(Event::Ui(Ui::Pan(x - x0, y - y0)));
                } else {
                    inbox.push(Event::Ui(Ui::Orbit(x - x0, y - y0)));
                }
                map.insert(e.pointer_id(), (x, y));
            }),
        );
    }
    let inbox = Rc::clone(inbox);
    let wheel = Closure::<dyn FnMut(web_sys::WheelEvent)>::new(move |e: web_sys::WheelEvent| {
        e.prevent_default();
        inbox.push(Event::Ui(Ui::Zoom((e.delta_y() as f32 * 0.001).exp())));
    });
    let options = web_sys::AddEventListenerOptions::new();
    options.set_passive(false);
    canvas.add_event_listener_with_callback_and_add_event_listener_options("wheel", wheel.as_ref().unchecked_ref(), &options).ok();
    wheel.forget();
    let no_menu = Closure::<dyn FnMut(web_sys::Event)>::new(|e: web_sys::Event| e.prevent_default());
    canvas.add_event_listener_with_callback("contextmenu", no_menu.as_ref().unchecked_ref()).ok();
    no_menu.forget();
}

/// Offers `bytes` as a download named `name`.
pub(crate) fn download(name: &str, bytes: &[u8], mime: &str) -> Result<(), JsValue> {
    let parts = js_sys::Array::of1(&js_sys::Uint8Array::from(bytes));
    let options = web_sys::BlobPropertyBag::new();
    options.set_type(mime);
    let blob = web_sys::Blob::new_with_u8_array_sequence_and_options(&parts, &options)?;
    let url = web_sys::Url::create_object_url_with_blob(&blob)?;
    let anchor: web_sys::HtmlAnchorElement = document().create_element("a")?.dyn_into()?;
    anchor.set_href(&url);
    anchor.set_download(name);
    anchor.click();
    web_sys::Url::revoke_object_url(&url)
}

/// The bytes at `url` (a GET); an HTTP error is named with the server's text.
pub(crate) async fn fetch_bytes(url: &str) -> Result<Vec<u8>, String> {
    let window = web_sys::window().ok_or("no window")?;
    let response = wasm_bindgen_futures::JsFuture::from(window.fetch_with_str(url)).await.map_err(|e| format!("{url}: {}", crate::link::js_text(&e)))?;
    let response: web_sys::Response = response.dyn_into().map_err(|_| format!("{url}: no response"))?;
    if !response.ok() {
        let text = match response.text() {
            Ok(promise) => wasm_bindgen_futures::JsFuture::from(promise).await.ok().and_then(|t| t.as_string()).unwrap_or_default(),
            Err(_) => String::new(),
        };
        return Err(format!("{url}: HTTP {} {}", response.status(), text.trim()));
    }
    let buffer = wasm_bindgen_futures::JsFuture::from(response.array_buffer().map_err(|e| crate::link::js_text(&e))?).await.map_err(|e| format!("{url}: {}", crate::link::js_text(&e)))?;
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
}

/// The name and bytes of the file chosen in file input `id` (`None`: none chosen).
pub(crate) async fn chosen_file(id: &str) -> Result<Option<(String, Vec<u8>)>, String> {
    let input: web_sys::HtmlInputElement = element(id)?;
    let Some(file) = input.files().and_then(|files| files.get(0)) else { return Ok(None) };
    let buffer = wasm_bindgen_futures::JsFuture::from(file.array_buffer()).await.map_err(|e| format!("{}: {}", file.name(), crate::link::js_text(&e)))?;
    Ok(Some((file.name(), js_sys::Uint8Array::new(&buffer).to_vec())))
}
