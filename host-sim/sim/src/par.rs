//! Parallel maps on rayon's pool for the host crates (simulator runs, diagnoses, blind
//! benchmark, the papers' sweeps): results keep the input order, and a worker that
//! panics becomes an error naming its item — never a dropped or default result. Every job
//! runs to its end; the error returned is the first in item order (rayon's own `Result`
//! collection would return whichever failed first in time), so a run is reproducible.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

use anyhow::{Result, anyhow};
use rayon::prelude::*;

/// The text of a panic payload (`&str` or `String`; anything else is named as such).
fn panic_message(p: &(dyn Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".into()
    }
}

/// `f` over `items` (by reference) in parallel, results in the items' order. The first
/// error in item order is returned; a panic is an error naming the item by `name`.
pub fn try_map<T, R, F, N>(items: &[T], name: N, f: F) -> Result<Vec<R>>
where
    T: Sync,
    R: Send,
    F: Fn(&T) -> Result<R> + Sync,
    N: Fn(&T) -> String + Sync,
{
    let results: Vec<Result<R>> = items
        .par_iter()
        .map(|it| {
            catch_unwind(AssertUnwindSafe(|| f(it)))
                .unwrap_or_else(|p| Err(anyhow!("{} panicked: {}", name(it), panic_message(&*p))))
        })
        .collect();
    results.into_iter().collect()
}

/// `f` on every item in parallel, results in the order of `items`. The first error (in
/// item order) is returned; a job that panics is an error naming its index and message.
pub fn try_par_map<T, R, F>(items: Vec<T>, f: F) -> Result<Vec<R>>
where
    T: Send,
    R: Send,
    F: Fn(T) -> Result<R> + Sync + Send,
{
    // every job runs to its end; the error reported is then the first in item order
    // (rayon's own Result collection would return whichever failed first in time)
    let results: Vec<Result<R>> = items
        .into_par_iter()
        .enumerate()
        .map(
            |(i, item)| match catch_unwind(AssertUnwindSafe(|| f(item))) {
                Ok(r) => r,
                Err(p) => Err(anyhow!("parallel job {i} panicked: {}", panic_message(&*p))),
            },
        )
        .collect();
    results.into_iter().collect()
}

/// As [`try_par_map`] for an infallible `f`: only a panic is an error.
pub fn par_map<T, R, F>(items: Vec<T>, f: F) -> Result<Vec<R>>
where
    T: Send,
    R: Send,
    F: Fn(T) -> R + Sync + Send,
{
    try_par_map(items, |x| Ok(f(x)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_keep_the_input_order() {
        let v = par_map((0..200).collect(), |i: u64| i * i).unwrap();
        assert_eq!(v, (0..200).map(|i| i * i).collect::<Vec<_>>());
    }

    #[test]
    fn a_panicking_job_is_an_error_not_a_missing_result() {
        let r = par_map((0..16).collect(), |i: usize| {
            if i == 11 {
                panic!("job {i} fails");
            }
            i
        });
        let e = r.expect_err("the panic must reach the caller");
        let msg = format!("{e:#}");
        assert!(
            msg.contains("job 11 fails") && msg.contains("parallel job 11"),
            "{msg}"
        );
    }

    #[test]
    fn the_first_error_in_item_order_is_returned() {
        let r = try_par_map((0..8).collect(), |i: usize| {
            if i >= 3 {
                Err(anyhow!("bad {i}"))
            } else {
                Ok(i)
            }
        });
        assert_eq!(r.unwrap_err().to_string(), "bad 3");
    }

    #[test]
    fn results_keep_the_items_order() {
        let v: Vec<u64> = (0..1000).collect();
        let out = try_map(&v, |i| format!("item {i}"), |&i| Ok(i * i)).unwrap();
        assert_eq!(out, v.iter().map(|i| i * i).collect::<Vec<_>>());
    }

    #[test]
    fn a_panicking_item_is_an_error_that_names_it() {
        let v: Vec<u32> = (0..64).collect();
        let err = try_map(
            &v,
            |i| format!("item {i}"),
            |&i| {
                if i == 37 {
                    panic!("boom at {i}");
                }
                Ok(i)
            },
        )
        .unwrap_err()
        .to_string();
        assert_eq!(err, "item 37 panicked: boom at 37");
    }

    #[test]
    fn an_error_is_returned_not_dropped() {
        let v: Vec<u32> = (0..8).collect();
        let err = try_map(
            &v,
            |i| format!("item {i}"),
            |&i| {
                anyhow::ensure!(i != 5, "item {i} is bad");
                Ok(i)
            },
        )
        .unwrap_err();
        assert_eq!(err.to_string(), "item 5 is bad");
    }
}
