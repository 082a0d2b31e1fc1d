//! The boundary itself: status codes, the per-thread error message, the wrapper that keeps
//! panics from crossing into C, and checked conversions of the caller's pointers.

use mres_format::MresError;
use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// What a call did. `MRES_OK` is zero; every other value is a failure, and
/// `mres_last_error_message()` then gives the full text.
#[repr(C)]
#[allow(non_camel_case_types)] // C enumerator names: the header exposes them as they are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MresStatus {
    /// Success.
    MRES_OK = 0,
    /// The bytes end before a section they declare (for a prefix: pass more bytes).
    MRES_ERR_TRUNCATED = 1,
    /// A value or reference in the file is out of range or inconsistent, or a page does not
    /// decompress to its declared size.
    MRES_ERR_CORRUPT = 2,
    /// The file is of a format version this library does not read (`mres_format_version()`).
    MRES_ERR_VERSION = 3,
    /// Not a `.mres` file (bad magic).
    MRES_ERR_BAD_MAGIC = 4,
    /// A checksum does not match: the prefix, or the page bytes given, are damaged.
    MRES_ERR_CHECKSUM = 5,
    /// The bytes given for a page are not exactly as long as its page-table entry says.
    MRES_ERR_PAGE_LENGTH = 6,
    /// A bad argument: a null pointer, or a group, cluster or page index out of range.
    MRES_ERR_ARG = 7,
    /// A caller buffer is smaller than the data; the count output holds the size needed.
    MRES_ERR_BUFFER_TOO_SMALL = 8,
    /// A bug in this library (a caught panic); the message says where.
    MRES_ERR_INTERNAL = 9,
}

/// The status of a reader error.
fn status_of(e: &MresError) -> MresStatus {
    match e {
        MresError::Truncated { .. } => MresStatus::MRES_ERR_TRUNCATED,
        MresError::WrongVersion { .. } => MresStatus::MRES_ERR_VERSION,
        MresError::BadMagic => MresStatus::MRES_ERR_BAD_MAGIC,
        MresError::Checksum(_) => MresStatus::MRES_ERR_CHECKSUM,
        MresError::PageLength { .. } => MresStatus::MRES_ERR_PAGE_LENGTH,
        // The caller passed the wrong pages as a page's sources.
        MresError::SourceCount { .. } | MresError::SourceLength { .. } => MresStatus::MRES_ERR_ARG,
        // Corrupt, Decompress, and any kind a later reader adds: the data is unusable. (Io
        // cannot occur: the library reads no files.)
        _ => MresStatus::MRES_ERR_CORRUPT,
    }
}

/// A failed call: its status and what went wrong.
#[derive(Debug)]
pub(crate) struct Failure {
    status: MresStatus,
    message: String,
}

impl Failure {
    /// A failure with `status` and `message`.
    pub(crate) fn new(status: MresStatus, message: impl Into<String>) -> Failure {
        Failure { status, message: message.into() }
    }

    /// A bad argument.
    pub(crate) fn arg(message: impl Into<String>) -> Failure {
        Failure::new(MresStatus::MRES_ERR_ARG, message)
    }
}

impl From<MresError> for Failure {
    fn from(e: MresError) -> Failure {
        Failure::new(status_of(&e), e.to_string())
    }
}

/// What a call's body returns.
pub(crate) type Outcome = Result<(), Failure>;

thread_local! {
    /// The message of this thread's latest failed call.
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: String) {
    // A message never holds NUL (reader messages are built from numbers and names), but a
    // CString must not: drop any rather than lose the message.
    let message = CString::new(message.replace('\0', "")).unwrap_or_default();
    LAST_ERROR.with(|last| *last.borrow_mut() = message);
}

/// Runs the body of the exported function `name`: its failure, or a panic inside it, becomes a
/// status and this thread's last error message instead of unwinding into the caller.
pub(crate) fn call(name: &str, body: impl FnOnce() -> Outcome) -> MresStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => MresStatus::MRES_OK,
        Ok(Err(failure)) => {
            set_last_error(format!("{name}: {}", failure.message));
            failure.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            set_last_error(format!("{name}: internal error (panic): {what}"));
            MresStatus::MRES_ERR_INTERNAL
        }
    }
}

/// The full text of this thread's most recent failed call, as a NUL-terminated UTF-8 string,
/// or "" before any call failed on this thread. Successful calls leave it unchanged.
///
/// The string belongs to the library: it stays valid until the next failing call on the same
/// thread; copy it to keep it. Never null.
#[no_mangle]
pub extern "C" fn mres_last_error_message() -> *const c_char {
    // Reading a thread-local cannot fail outside thread teardown; there, answer "".
    LAST_ERROR.try_with(|last| last.borrow().as_ptr()).unwrap_or(c"".as_ptr())
}

/// The enumerator name of `status` ("MRES_OK", "MRES_ERR_TRUNCATED", ...), or
/// "MRES_ERR_UNKNOWN" for a value that is none of them. A static string; never null.
///
/// Takes an `int` rather than the enum so that any value a caller holds is safe to pass.
#[no_mangle]
pub extern "C" fn mres_status_name(status: i32) -> *const c_char {
    let name: &'static CStr = match status {
        0 => c"MRES_OK",
        1 => c"MRES_ERR_TRUNCATED",
        2 => c"MRES_ERR_CORRUPT",
        3 => c"MRES_ERR_VERSION",
        4 => c"MRES_ERR_BAD_MAGIC",
        5 => c"MRES_ERR_CHECKSUM",
        6 => c"MRES_ERR_PAGE_LENGTH",
        7 => c"MRES_ERR_ARG",
        8 => c"MRES_ERR_BUFFER_TOO_SMALL",
        9 => c"MRES_ERR_INTERNAL",
        _ => c"MRES_ERR_UNKNOWN",
    };
    name.as_ptr()
}

/// The `len` bytes at `ptr` (a null `ptr` is allowed only with `len` 0).
///
/// # Safety
/// A non-null `ptr` must point to `len` readable bytes that stay unchanged during the call.
pub(crate) unsafe fn bytes<'a>(ptr: *const u8, len: usize, what: &str) -> Result<&'a [u8], Failure> {
    if len == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(Failure::arg(format!("{what} is null but its length is {len}")));
    }
    if len > isize::MAX as usize {
        return Err(Failure::arg(format!("{what}: length {len} is larger than any buffer")));
    }
    // SAFETY: non-null, length in range; validity is the caller's contract.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// The object behind a handle or input pointer, or an `MRES_ERR_ARG` failure if it is null.
///
/// # Safety
/// A non-null `ptr` must point to a live `T`.
pub(crate) unsafe fn get<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller's contract.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::arg(format!("{what} is null")))
}

/// Stores `value` through the output pointer `ptr`, or fails with `MRES_ERR_ARG` if it is null.
///
/// # Safety
/// A non-null `ptr` must be valid for a write of a `T`.
pub(crate) unsafe fn put<T>(ptr: *mut T, what: &str, value: T) -> Outcome {
    if ptr.is_null() {
        return Err(Failure::arg(format!("{what} is null")));
    }
    // SAFETY: non-null; writability and alignment are the caller's contract. `write` does not
    // drop the caller's (possibly uninitialized) old value.
    unsafe { ptr.write(value) };
    Ok(())
}

/// Copies `src` into the caller's array `out` of `cap` elements and stores `src.len()` in
/// `*count`, always (also on failure, so that a caller learns the size needed).
///
/// `out` null with `cap` 0 asks for the size alone and succeeds. A `cap` below `src.len()`
/// fails with `MRES_ERR_BUFFER_TOO_SMALL`, writing nothing into `out`.
///
/// # Safety
/// A non-null `out` must be valid for writes of `cap` elements; `count` for a write of a
/// `usize`.
pub(crate) unsafe fn copy_out<T: Copy>(src: &[T], out: *mut T, cap: usize, count: *mut usize) -> Outcome {
    // SAFETY: the caller's contract.
    if unsafe { room(src.len(), out, cap, count)? } {
        // SAFETY: `out` is non-null and holds `cap >= src.len()` elements (the caller's
        // contract); a caller's buffer cannot overlap the library's own data.
        unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), out, src.len()) };
    }
    Ok(())
}

/// [`copy_out`]'s checks for `len` elements, before they exist (a caller that would decode
/// them first asks here): stores `len` in `*count`; `false` for a size query (`out` null,
/// `cap` 0), `true` where `out` holds them, else the failure.
///
/// # Safety
/// As for [`copy_out`].
pub(crate) unsafe fn room<T>(len: usize, out: *mut T, cap: usize, count: *mut usize) -> Result<bool, Failure> {
    // SAFETY: the caller's contract.
    unsafe { put(count, "count", len)? };
    if out.is_null() && cap == 0 {
        return Ok(false);
    }
    if len > cap {
        return Err(Failure::new(
            MresStatus::MRES_ERR_BUFFER_TOO_SMALL,
            format!("the buffer holds {cap} elements, {len} are needed"),
        ));
    }
    if out.is_null() {
        return Err(Failure::arg(format!("out is null but cap is {cap}")));
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panics_become_a_status_and_a_message() {
        let status = call("mres_test", || panic!("boom"));
        assert_eq!(status, MresStatus::MRES_ERR_INTERNAL);
        // SAFETY: the library's message is a valid C string.
        let message = unsafe { CStr::from_ptr(mres_last_error_message()) };
        assert_eq!(message.to_str().unwrap(), "mres_test: internal error (panic): boom");
    }

    #[test]
    fn status_names_match_the_enumerators() {
        let all = [
            MresStatus::MRES_OK,
            MresStatus::MRES_ERR_TRUNCATED,
            MresStatus::MRES_ERR_CORRUPT,
            MresStatus::MRES_ERR_VERSION,
            MresStatus::MRES_ERR_BAD_MAGIC,
            MresStatus::MRES_ERR_CHECKSUM,
            MresStatus::MRES_ERR_PAGE_LENGTH,
            MresStatus::MRES_ERR_ARG,
            MresStatus::MRES_ERR_BUFFER_TOO_SMALL,
            MresStatus::MRES_ERR_INTERNAL,
        ];
        for status in all {
            // SAFETY: static C strings.
            let name = unsafe { CStr::from_ptr(mres_status_name(status as i32)) };
            assert_eq!(name.to_str().unwrap(), format!("{status:?}"));
        }
        // SAFETY: as above.
        let unknown = unsafe { CStr::from_ptr(mres_status_name(all.len() as i32)) };
        assert_eq!(unknown.to_str().unwrap(), "MRES_ERR_UNKNOWN");
    }
}
