//! Vulkan validation: the debug-utils messenger that turns layer messages into counted errors.
//! Tests and `demo --validation` treat any error here as a failure.

use ash::vk;
use std::ffi::CStr;
use std::sync::Mutex;

/// What the validation layer reported over a context's life.
#[derive(Default, Debug)]
pub struct ValidationLog {
    errors: Mutex<Vec<String>>,
    warnings: Mutex<u32>,
}

impl ValidationLog {
    pub fn error_count(&self) -> usize {
        self.errors.lock().unwrap().len()
    }
    pub fn errors(&self) -> Vec<String> {
        self.errors.lock().unwrap().clone()
    }
    pub fn warning_count(&self) -> u32 {
        *self.warnings.lock().unwrap()
    }
}

/// Called by the validation layer on any thread. `user_data` is the `ValidationLog` owned by
/// the `Gpu` context, which outlives the messenger.
pub(crate) unsafe extern "system" fn messenger_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user_data: *mut std::ffi::c_void,
) -> vk::Bool32 {
    let log = &*(user_data as *const ValidationLog);
    let message = if data.is_null() || (*data).p_message.is_null() {
        "(no message)".to_string()
    } else {
        CStr::from_ptr((*data).p_message).to_string_lossy().into_owned()
    };
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        eprintln!("[vulkan validation error] {kind:?}: {message}");
        log.errors.lock().unwrap().push(message);
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        eprintln!("[vulkan validation warning] {kind:?}: {message}");
        *log.warnings.lock().unwrap() += 1;
    }
    vk::FALSE
}
