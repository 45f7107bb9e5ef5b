//! Memory on large inputs (issue 37, item 9): what reading a CSV file and detecting the
//! period of a long record hold at their peak, counted by this binary's allocator (the
//! bytes asked for, whatever the machine), against bounds per row or sample that the
//! whole-file read (the text, then the columns) and the whole-length transform (32 bytes a
//! sample for the padded buffer, as much for each plan and the scratch) exceeded.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use jointid::data::{ColumnMap, Loaders};
use jointid::ident::frf::detect_period;

/// The system allocator, counting the bytes held and their peak.
struct Counting;

static HELD: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn held(delta: isize) {
    let now = if delta >= 0 {
        HELD.fetch_add(delta as usize, Ordering::SeqCst) + delta as usize
    } else {
        HELD.fetch_sub((-delta) as usize, Ordering::SeqCst) - (-delta) as usize
    };
    PEAK.fetch_max(now, Ordering::SeqCst);
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            held(layout.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        held(-(layout.size() as isize));
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            held(new_size as isize - layout.size() as isize);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One measurement at a time (the test harness runs tests on threads).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The bytes `work` holds at its peak beyond what was held when it began, and its result.
fn peak_of<T>(work: impl FnOnce() -> T) -> (usize, T) {
    let base = HELD.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    let out = work();
    (PEAK.load(Ordering::SeqCst) - base, out)
}

#[test]
fn reading_a_csv_file_holds_its_columns_not_its_text() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let rows = 300_000;
    let path = std::env::temp_dir().join(format!("jointid-memory-{}.csv", std::process::id()));
    let mut text = String::from("time_s,torque,angle,unused\n");
    for k in 0..rows {
        let t = k as f64 * 5e-4;
        text.push_str(&format!(
            "{t},{},{},0.0\n",
            (7.0 * t).sin() * 0.0123456789,
            (3.0 * t).cos() * 1.23456789e-3
        ));
    }
    std::fs::write(&path, &text).unwrap();
    let per_row_text = text.len() / rows;
    drop(text);
    let map = ColumnMap {
        time: "time_s".into(),
        input: "torque".into(),
        output: "angle".into(),
        reference: None,
        delimiter: None,
    };
    let loaders = Loaders::default();
    let (peak, record) = peak_of(|| loaders.load_record(&path, &map));
    std::fs::remove_file(&path).unwrap();
    let record = record.unwrap();
    assert_eq!(record.pieces[0].data.len(), rows);
    // three columns of f64 are 24 bytes a row; the text alone is more than twice that
    let per_row = peak / rows;
    assert!(per_row_text > 2 * 24, "{per_row_text} bytes of text a row");
    assert!(
        per_row <= 2 * 24,
        "reading held {peak} bytes at its peak, {per_row} a row (text: {per_row_text} a row)"
    );
}

#[test]
fn detecting_the_period_of_a_long_record_needs_no_whole_length_transform() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (n, period) = (3_000_000, 5000);
    let x: Vec<f64> = (0..n)
        .map(|k| {
            let p = (k % period) as f64 / period as f64;
            (2.0 * std::f64::consts::PI * 3.0 * p).sin()
                + 0.5 * (2.0 * std::f64::consts::PI * 11.0 * p + 1.0).sin()
        })
        .collect();
    let (peak, found) = peak_of(|| detect_period(&x, "u"));
    assert_eq!(found.unwrap(), period);
    // the half spectra of the blocks (16 bytes a sample) and the lags (4), and the
    // transforms of one block; the whole-length transform held 144 bytes a sample
    let per_sample = peak / n;
    assert!(
        per_sample <= 40,
        "detection held {peak} bytes at its peak, {per_sample} a sample"
    );
}
