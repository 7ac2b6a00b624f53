//! Parallel maps on rayon's pool whose failures reach the caller: a worker that panics
//! becomes an error naming its item (never a dropped or default result), and the results
//! come back in the items' order.

use std::panic::{AssertUnwindSafe, catch_unwind};

use rayon::prelude::*;

/// The message of a panic payload.
fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}

/// `f` over `items` in parallel, results in the items' order. The first error (or panic,
/// reported as an error naming the item by `name`) is returned.
pub fn try_map<T, R, F, N>(items: &[T], name: N, f: F) -> anyhow::Result<Vec<R>>
where
    T: Sync,
    R: Send,
    F: Fn(&T) -> anyhow::Result<R> + Sync,
    N: Fn(&T) -> String + Sync,
{
    items
        .par_iter()
        .map(|it| {
            catch_unwind(AssertUnwindSafe(|| f(it))).unwrap_or_else(|p| {
                Err(anyhow::anyhow!(
                    "{} panicked: {}",
                    name(it),
                    panic_message(p.as_ref())
                ))
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
