//! The module's allocator: the system's, with large blocks on transparent huge pages and reused
//! within a solve.
//!
//! A solve of 10^6 nodes allocates several hundred MB in large blocks (the Newton systems' storage,
//! the evaluated points, the start's work arrays), most of them freed again before the solve ends.
//! Fresh memory costs the kernel a fault and a clearing per page, and that was a third of a large
//! solve's time. So:
//!
//! * large blocks ask for transparent huge pages (`madvise`; Linux's default setting gives them
//!   only to memory that asks, as numpy's large arrays do): one fault per 2 MiB, and the clearing of
//!   a big block runs three to four times as fast;
//! * while a [`Reuse`] guard lives (the front end holds one for each solve), a block of at least
//!   [`REUSE`] bytes that is freed is kept and handed to the next such allocation it fits, instead of going back to the
//!   system and coming back as fresh pages. When the guard ends, the blocks that were in use during
//!   that solve stay kept for the next one (a study solves the same chain again and again); those
//!   it did not use are freed. So at most what one solve needed (and never more than [`KEPT`]) stays
//!   allocated between solves.
//!
//! The numbers computed do not change (a reused block asked for zeroed memory is zeroed).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;

/// Blocks of at least this many bytes are aligned to a huge page and advised to use huge pages.
const LARGE: usize = 4 << 20;
/// Blocks of at least this many bytes are reused while a guard lives (a chain of 10^5 nodes works
/// on arrays of about a megabyte, which the system would otherwise hand back and fault in afresh).
const REUSE: usize = 256 << 10;
const HUGE_PAGE: usize = 2 << 20;
/// Large blocks kept at most (a solve's temporaries are a few dozen), and their bytes at most.
const SLOTS: usize = 256;
pub const KEPT: usize = 2 << 30;

pub struct HugePages;

/// Freed large blocks kept for reuse: address, usable size, and whether it was in use during the
/// current solve.
struct Pool {
    guards: usize,
    blocks: [(usize, usize, bool); SLOTS],
    len: usize,
    bytes: usize,
}

static POOL: Mutex<Pool> = Mutex::new(Pool {
    guards: 0,
    blocks: [(0, 0, false); SLOTS],
    len: 0,
    bytes: 0,
});

/// While a `Reuse` lives, freed large blocks are kept for the next large allocations.
pub struct Reuse;

impl Reuse {
    pub fn begin() -> Reuse {
        lock().guards += 1;
        Reuse
    }
}

impl Drop for Reuse {
    fn drop(&mut self) {
        let mut pool = lock();
        pool.guards -= 1;
        if pool.guards > 0 {
            return;
        }
        // free what this solve did not use; mark the rest unused for the next one
        let mut k = 0;
        while k < pool.len {
            let (address, size, used) = pool.blocks[k];
            if used {
                pool.blocks[k].2 = false;
                k += 1;
                continue;
            }
            // (free() needs no size; the layout only says the block was aligned)
            unsafe { System.dealloc(address as *mut u8, large(size)) };
            pool.bytes -= size;
            let last = pool.len - 1;
            pool.blocks[k] = pool.blocks[last];
            pool.len = last;
        }
    }
}

fn lock() -> std::sync::MutexGuard<'static, Pool> {
    POOL.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The layout of a large block of `size` bytes.
fn large(size: usize) -> Layout {
    Layout::from_size_align(size, HUGE_PAGE).expect("a large block's layout")
}

/// The layout a block of `layout` is allocated with: aligned to a huge page if it is large.
fn actual(layout: Layout) -> Option<Layout> {
    if layout.size() < LARGE || !cfg!(target_os = "linux") {
        return Some(layout);
    }
    Layout::from_size_align(layout.size(), layout.align().max(HUGE_PAGE)).ok()
}

/// A kept block for `layout`: the smallest that holds it, if not more than twice as large.
fn reused(layout: Layout) -> Option<*mut u8> {
    if layout.size() < REUSE || layout.align() > HUGE_PAGE || !cfg!(target_os = "linux") {
        return None;
    }
    let mut pool = lock();
    let mut best: Option<usize> = None;
    for k in 0..pool.len {
        let (address, size, _) = pool.blocks[k];
        // (a block kept from a smaller allocation may be aligned less than this one asks)
        let aligned = address % layout.align() == 0;
        if aligned
            && size >= layout.size()
            && size <= 2 * layout.size()
            && best.is_none_or(|b| size < pool.blocks[b].1)
        {
            best = Some(k);
        }
    }
    let k = best?;
    let (address, size, _) = pool.blocks[k];
    pool.bytes -= size;
    let last = pool.len - 1;
    pool.blocks[k] = pool.blocks[last];
    pool.len = last;
    Some(address as *mut u8)
}

/// Keeps a freed large block if a guard lives and there is room; false if it must be freed.
unsafe fn kept(pointer: *mut u8, layout: Layout) -> bool {
    if layout.size() < REUSE || !cfg!(target_os = "linux") {
        return false;
    }
    let mut pool = lock();
    let size = usable_size(pointer);
    if pool.guards == 0 || pool.len == SLOTS || pool.bytes + size > KEPT {
        return false;
    }
    let len = pool.len;
    pool.blocks[len] = (pointer as usize, size, true);
    pool.len += 1;
    pool.bytes += size;
    true
}

#[cfg(target_os = "linux")]
unsafe fn usable_size(pointer: *mut u8) -> usize {
    libc::malloc_usable_size(pointer.cast())
}

#[cfg(not(target_os = "linux"))]
unsafe fn usable_size(_: *mut u8) -> usize {
    0
}

/// Advises the kernel to back a large block with huge pages (a hint: nothing fails if it does not).
unsafe fn advise(pointer: *mut u8, layout: Layout) {
    #[cfg(target_os = "linux")]
    if !pointer.is_null() && layout.size() >= LARGE {
        libc::madvise(pointer.cast(), layout.size(), libc::MADV_HUGEPAGE);
    }
}

unsafe impl GlobalAlloc for HugePages {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if let Some(pointer) = reused(layout) {
            return pointer;
        }
        let Some(layout) = actual(layout) else {
            return std::ptr::null_mut();
        };
        let pointer = System.alloc(layout);
        advise(pointer, layout);
        pointer
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if let Some(pointer) = reused(layout) {
            std::ptr::write_bytes(pointer, 0, layout.size());
            return pointer;
        }
        let Some(layout) = actual(layout) else {
            return std::ptr::null_mut();
        };
        let pointer = System.alloc_zeroed(layout);
        advise(pointer, layout);
        pointer
    }

    unsafe fn dealloc(&self, pointer: *mut u8, layout: Layout) {
        if kept(pointer, layout) {
            return;
        }
        if let Some(layout) = actual(layout) {
            System.dealloc(pointer, layout);
        }
    }

    unsafe fn realloc(&self, pointer: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if layout.size() < REUSE && new_size < REUSE {
            return System.realloc(pointer, layout, new_size);
        }
        // to or from a large block: a new block, with the contents copied
        let Ok(new_layout) = Layout::from_size_align(new_size, layout.align()) else {
            return std::ptr::null_mut();
        };
        let new = self.alloc(new_layout);
        if !new.is_null() {
            std::ptr::copy_nonoverlapping(pointer, new, layout.size().min(new_size));
            self.dealloc(pointer, layout);
        }
        new
    }
}
