//! EXT_meshopt_compression (what `gltfpack -c` writes): a buffer view whose bytes are stored
//! compressed by meshoptimizer's vertex or index codec, optionally filtered, in another
//! buffer; the view's own buffer is then usually a placeholder without data (`fallback`).
//! The views are decoded here into their buffer, so that the accessor checks and the reader
//! see plain views. meshoptimizer's decoders are written for untrusted input (a malformed
//! stream is an error, never a read or write outside the given ranges), but they assert on
//! their size parameters, so every size is checked here first.

use std::borrow::Cow;

use serde::Deserialize;

use super::super::{ImportErrorKind, KindResult};

/// The extension's block on one buffer view.
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct Compression {
    buffer: usize,
    #[serde(default)]
    byte_offset: usize,
    byte_length: usize,
    byte_stride: usize,
    count: usize,
    mode: String,
    #[serde(default)]
    filter: Option<String>,
}

#[derive(Deserialize)]
struct Extensions<T> {
    #[serde(rename = "EXT_meshopt_compression")]
    meshopt: Option<T>,
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct ViewJson {
    buffer: usize,
    #[serde(default)]
    byte_offset: usize,
    byte_length: usize,
    extensions: Option<Extensions<Compression>>,
}

#[derive(Deserialize)]
struct Fallback {
    #[serde(default)]
    fallback: bool,
}

#[derive(Deserialize)]
struct BufferJson {
    extensions: Option<Extensions<Fallback>>,
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct RootJson {
    #[serde(default)]
    buffers: Vec<BufferJson>,
    #[serde(default)]
    buffer_views: Vec<ViewJson>,
}

/// One compressed view: where its decoded bytes go and where they come from.
struct View {
    index: usize,
    /// The view's buffer, offset and length: where the decoded bytes go.
    target: (usize, usize, usize),
    compression: Compression,
}

/// The file's compressed views, and which buffers are placeholders without data.
#[derive(Default)]
pub(super) struct Compressed {
    views: Vec<View>,
    fallback: Vec<bool>,
}

impl Compressed {
    /// Reads the extension's blocks from the glTF JSON (valid JSON: the crate parsed it).
    pub(super) fn new(json_bytes: &[u8]) -> KindResult<Compressed> {
        let root: RootJson = super::extension_json(json_bytes)?;
        let fallback = root
            .buffers
            .iter()
            .map(|b| b.extensions.as_ref().and_then(|e| e.meshopt.as_ref()).is_some_and(|f| f.fallback))
            .collect();
        let views = root
            .buffer_views
            .into_iter()
            .enumerate()
            .filter_map(|(index, v)| {
                let compression = v.extensions?.meshopt?;
                Some(View { index, target: (v.buffer, v.byte_offset, v.byte_length), compression })
            })
            .collect();
        Ok(Compressed { views, fallback })
    }

    /// Marks the buffers the compressed views of used buffers read from as used.
    pub(super) fn mark_sources(&self, used: &mut [bool]) {
        for view in &self.views {
            if used.get(view.target.0).copied().unwrap_or(false) {
                if let Some(source) = used.get_mut(view.compression.buffer) {
                    *source = true;
                }
            }
        }
    }

    /// Whether buffer `b` holds no data of its own (its views are all decoded into it).
    pub(super) fn is_placeholder(&self, b: usize) -> bool {
        self.fallback.get(b).copied().unwrap_or(false)
    }

    /// Decodes every compressed view of the used buffers into its buffer: `buffers` holds the
    /// loaded data of each used buffer, and `None` for placeholders, which become zeros of
    /// their declared `lengths` (at most `max_bytes`, as a buffer file) before their views are
    /// decoded into them.
    pub(super) fn decode(
        &self,
        buffers: &mut [Option<Cow<'_, [u8]>>],
        lengths: &[usize],
        used: &[bool],
        max_bytes: u64,
    ) -> KindResult<()> {
        for (b, data) in buffers.iter_mut().enumerate() {
            if used[b] && self.is_placeholder(b) {
                if lengths[b] as u64 > max_bytes {
                    return Err(ImportErrorKind::TooLarge(format!(
                        "buffer {b} (EXT_meshopt_compression) declares {} bytes, over the {max_bytes}-byte limit",
                        lengths[b]
                    )));
                }
                *data = Some(Cow::Owned(vec![0; lengths[b]]));
            }
        }
        for view in self.views.iter().filter(|v| used.get(v.target.0).copied().unwrap_or(false)) {
            view.decode_into(buffers).map_err(|reason| {
                ImportErrorKind::Parse(format!("bufferView {} (EXT_meshopt_compression): {reason}", view.index))
            })?;
        }
        Ok(())
    }
}

impl View {
    /// Decodes this view from its source buffer into its own (both loaded in `buffers`).
    fn decode_into(&self, buffers: &mut [Option<Cow<'_, [u8]>>]) -> Result<(), String> {
        let c = &self.compression;
        let loaded = |b: usize| format!("buffer {b} is not loaded");
        let source = buffers.get(c.buffer).and_then(|d| d.as_deref()).ok_or_else(|| loaded(c.buffer))?;
        let (offset, length) = (c.byte_offset, c.byte_length);
        let encoded = source.get(offset..offset.saturating_add(length)).ok_or_else(|| {
            format!("{length} bytes from offset {offset} run past buffer {} ({} bytes)", c.buffer, source.len())
        })?;
        let (t, offset, length) = self.target;
        let decoded = decode(c, encoded, length)?;
        let target = buffers.get_mut(t).and_then(|d| d.as_mut()).ok_or_else(|| loaded(t))?;
        let slot = target.to_mut().get_mut(offset..offset.saturating_add(decoded.len()));
        slot.ok_or_else(|| format!("offset {offset} and {length} bytes run past buffer {t}"))?
            .copy_from_slice(&decoded);
        Ok(())
    }
}

/// Decodes one view's `encoded` bytes: `count` elements of `byte_stride` bytes, which must
/// fit the view's `length`.
fn decode(c: &Compression, encoded: &[u8], length: usize) -> Result<Vec<u8>, String> {
    let (count, stride) = (c.count, c.byte_stride);
    let size = count
        .checked_mul(stride)
        .filter(|&s| s <= length)
        .ok_or_else(|| format!("{count} elements of {stride} bytes do not fit its {length} bytes"))?;
    // The mode's decoder, after the checks of the sizes it asserts on; all three share one
    // signature (destination, count, element size, stream, stream length).
    type Decoder = unsafe extern "C" fn(*mut std::ffi::c_void, usize, usize, *const u8, usize) -> std::ffi::c_int;
    let indices = |decoder: Decoder| match stride {
        2 | 4 => Ok(decoder),
        _ => Err(format!("byteStride {stride} of indices is not 2 or 4")),
    };
    let decoder: Decoder = match c.mode.as_str() {
        "ATTRIBUTES" if stride == 0 || stride > 256 || !stride.is_multiple_of(4) => {
            return Err(format!("byteStride {stride} is not a multiple of 4 from 4 to 256"));
        }
        "ATTRIBUTES" => ::meshopt::ffi::meshopt_decodeVertexBuffer,
        "TRIANGLES" if !count.is_multiple_of(3) => {
            return Err(format!("count {count} of TRIANGLES is not a multiple of 3"));
        }
        "TRIANGLES" => indices(::meshopt::ffi::meshopt_decodeIndexBuffer)?,
        "INDICES" => indices(::meshopt::ffi::meshopt_decodeIndexSequence)?,
        other => return Err(format!("unknown mode {other:?}")),
    };
    let mut out = vec![0u8; size];
    // SAFETY: `out` holds `count` elements of `stride` bytes, a size the decoder accepts
    // (checked above); it reads at most `encoded.len()` bytes and returns an error on a
    // malformed stream.
    let code = unsafe { decoder(out.as_mut_ptr().cast(), count, stride, encoded.as_ptr(), encoded.len()) };
    if code != 0 {
        return Err(format!("the {} stream does not decode (meshoptimizer error {code})", c.mode));
    }
    unfilter(c.filter.as_deref().unwrap_or("NONE"), &c.mode, &mut out, count, stride)?;
    Ok(out)
}

/// Undoes a view's filter in place (the extension's OCTAHEDRAL, QUATERNION and EXPONENTIAL
/// filters, for ATTRIBUTES only).
fn unfilter(filter: &str, mode: &str, data: &mut [u8], count: usize, stride: usize) -> Result<(), String> {
    let fits = match filter {
        "NONE" => return Ok(()),
        _ if mode != "ATTRIBUTES" => return Err(format!("filter {filter} on mode {mode}")),
        "OCTAHEDRAL" => stride == 4 || stride == 8,
        "QUATERNION" => stride == 8,
        "EXPONENTIAL" => stride.is_multiple_of(4),
        other => return Err(format!("unknown filter {other:?}")),
    };
    if !fits {
        return Err(format!("filter {filter} cannot have byteStride {stride}"));
    }
    let buffer = data.as_mut_ptr().cast();
    // SAFETY: `data` holds `count` elements of `stride` bytes, a stride each filter accepts
    // (checked above); the filters read and write those bytes only.
    unsafe {
        match filter {
            "OCTAHEDRAL" => ::meshopt::ffi::meshopt_decodeFilterOct(buffer, count, stride),
            "QUATERNION" => ::meshopt::ffi::meshopt_decodeFilterQuat(buffer, count, stride),
            _ => ::meshopt::ffi::meshopt_decodeFilterExp(buffer, count, stride),
        }
    }
    Ok(())
}
